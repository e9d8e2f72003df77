"""A calibration certificate per sensor (docs/calibration.md, "The
certificate"): U of the compensated tilt per axis by bands of IMU
temperature and nominal tilt, its budget, and the fields a laboratory's
certificate carries, as certificate.json, .html and .pdf; and where a
certificate's U applies (``u95_at``, ``change_u95``, ``in_domain``), for
``validate``."""

from __future__ import annotations

from .domain import change_u95, in_domain, read_certificate, u95_at
from .issue import Certification, NotCertifiable, certify, write_certificate

__all__ = [
    "Certification",
    "NotCertifiable",
    "certify",
    "change_u95",
    "in_domain",
    "read_certificate",
    "u95_at",
    "write_certificate",
]
