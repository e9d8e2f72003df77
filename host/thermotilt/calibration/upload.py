"""``thermotilt upload FIT_DIR --port PORT``: a fit's surfaces into the IMU
reader, each step checked before the next (docs/calibration.md, "Uploading").

1. The table: FIT_DIR/coefficients.json (``thermotilt fit``), as float32,
   the firmware's type; a surface the fit did not make (Z, an axis not
   fitted) is zero, as in coefficients.bin.
2. The board: a Nano resets when its port is opened and sends VER once it
   has booted; a board that does not reset (the twin's pty) shows itself by
   any frame. Its VERSION answer must name the imu_reader and this host's
   protocol.
3. Per set (W, C) and axis (X, Y, Z): SETCOE, then GETCOE, whose COE must
   equal what was sent. A refusal, a silence or a mismatch stops the upload
   before SAVECOE, so the EEPROM keeps what it held (the RAM keeps the
   surfaces sent so far, coef_source U, until the board resets).
4. SAVECOE, RESET, the VER of the restart (reset_cause COMMANDED), then
   coef_source E in ICF (STATUS) and in the IMU frames, and GETCOE again:
   the board now runs what it loaded from its EEPROM. Without saving, only
   STATUS: coef_source U.

"Equal" is to the COE frame's printed precision: the firmware writes each
coefficient with five significant digits, so a value read back is equal
when it lies within half a unit of the fifth significant digit of the
float32 that was sent (5e-5 of it at most). SETCOE itself carries the
float32 exactly (nine digits); that the saved block holds it bit for bit is
checked in the twin (host/tests/test_upload.py).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import serial

from ..surfaces import AXES, COEFFICIENT_NAMES, SETS, ZERO_SURFACE, CoefficientTable, Surface
from ..wire.client import CommandClient, CommandRefused, CommandTimeout
from ..wire.protocol import PROTOCOL_VERSION, Frame
from .compare import read_fit
from .dataset import CalibrationDataError

DEFAULT_BAUD = 115200
# A Nano's bootloader waits about a second after the reset that opening its
# port causes; the sketch's VER follows at once.
BOOT_WAIT_S = 2.5
# RESET restarts the board within the watchdog's 16 ms; the rest is margin
# for a bootloader and a loaded host.
RESTART_WAIT_S = 3.0
# After a restart the IMU frames come at 10 Hz, once the sensor has settled.
IMU_FRAME_WAIT_S = 3.0
# SAVECOE writes up to 148 EEPROM bytes at 3.3 ms each on the chip.
SAVE_TIMEOUT_S = 2.0
FLOAT32_MAX = 3.4028234663852886e38
# FrameWriter::addScientific's default, which the COE frame uses.
COE_SIGNIFICANT_DIGITS = 5

NOTHING_SAVED = "; nothing saved (the EEPROM holds what it held)"
SAVED_UNCHECKED = "; the coefficients are saved, but were not checked after a reset"
AFTER_RESET = "; the board runs other coefficients than were sent"


class UploadError(RuntimeError):
    """An upload that stopped: one readable line saying where and why."""


@dataclass(frozen=True)
class UploadResult:
    port: str
    firmware_version: str
    sent: CoefficientTable  # float32
    read_back: CoefficientTable
    after_reset: CoefficientTable | None  # None without saving
    saved: bool
    reset_cause: str | None
    coef_source: str
    imu_frames_checked: int


def read_table(fit_dir: Path) -> CoefficientTable:
    """The surfaces of FIT_DIR/coefficients.json as float32, zero where the fit made none."""
    path = fit_dir / "coefficients.json"
    try:
        fits = read_fit(fit_dir)
    except CalibrationDataError as error:
        raise UploadError(str(error)) from None
    if not fits:
        raise UploadError(f"{path}: no fitted surface to upload")
    surfaces = {(set_name, axis): ZERO_SURFACE for set_name in SETS for axis in AXES}
    for key, fit in fits.items():
        if (key[:1], key[1:]) not in surfaces:
            raise UploadError(f"{path}: unknown surface {key!r} (expected a set W or C and an axis X, Y or Z, e.g. WX)")
        surfaces[(key[:1], key[1:])] = fit.surface
    for (set_name, axis), surface in surfaces.items():
        for term, value in zip(COEFFICIENT_NAMES, surface, strict=True):
            if not math.isfinite(value) or abs(value) > FLOAT32_MAX:
                raise UploadError(
                    f"{path}: {set_name}{axis} {term} = {value:g}, which the firmware's float32 cannot hold"
                )
    return CoefficientTable(surfaces).to_float32()


def printed_equal(sent: float, printed: float, digits: int = COE_SIGNIFICANT_DIGITS) -> bool:
    """printed is sent written with `digits` significant digits: within half a unit of the last."""
    if sent == 0.0:
        return printed == 0.0
    half_unit = 0.5 * 10.0 ** (math.floor(math.log10(abs(sent))) - (digits - 1))
    # The slack covers the decimal-to-binary rounding of the printed text.
    return abs(printed - sent) <= half_unit * (1.0 + 1e-9)


def first_mismatch(sent: Surface, printed: Surface) -> str | None:
    for term, want, got in zip(COEFFICIENT_NAMES, sent, printed, strict=True):
        if not printed_equal(want, got):
            return f"{term} = {got:.4e}, sent {want:.9g}"
    return None


def _open(port: str, baud: int) -> Any:
    try:
        return serial.serial_for_url(port, baudrate=baud, timeout=0)
    # pyserial's URL handlers raise whatever their parsing meets, so any
    # failure here is the port's.
    except Exception as error:
        raise UploadError(f"cannot open {port}: {error}") from None


def upload(fit_dir: Path, port: str, baud: int = DEFAULT_BAUD, save: bool = True) -> UploadResult:
    """Reads FIT_DIR, opens PORT and uploads (upload_table); raises UploadError."""
    table = read_table(fit_dir)
    line = _open(port, baud)
    try:
        return upload_table(line, table, save=save, name=port)
    except (serial.SerialException, OSError) as error:
        raise UploadError(f"lost {port}: {error}") from None
    finally:
        line.close()


def upload_table(port: Any, table: CoefficientTable, save: bool = True, name: str = "the board") -> UploadResult:
    """Uploads a float32 table through a pyserial port or a twin Board
    (whose waits are then simulated time); raises UploadError."""
    return _Session(port, name).run(table, save)


class _Session:
    def __init__(self, port: Any, name: str):
        self.name = name
        # Every frame no command took: IMU and ERR frames, the VER of a boot.
        self.frames: list[Frame] = []
        self.client = CommandClient(port, on_frame=self.frames.append)

    def run(self, table: CoefficientTable, save: bool) -> UploadResult:
        version = self.hello()
        read_back = {}
        for set_name in SETS:
            for axis in AXES:
                surface = table.surface(set_name, axis)
                self.command(f"SETCOE {set_name} {axis}", "SETCOE", [set_name, axis, *surface], NOTHING_SAVED)
                read_back[(set_name, axis)] = self.read_back(set_name, axis, surface, "", NOTHING_SAVED)
        if not save:
            source = self.coef_source("; the coefficients are in RAM, not saved")
            if source != "U":
                raise UploadError(f"after the upload {self.name} runs coef_source {source}, not U")
            return UploadResult(
                self.name, version["firmware_version"], table, CoefficientTable(read_back), None, False, None, source, 0
            )
        saved_timeout = self.client.timeout_s
        self.client.timeout_s = SAVE_TIMEOUT_S
        try:
            self.command(
                "SAVECOE",
                "SAVECOE",
                (),
                "; the EEPROM may hold part of the block, which the board loads only if its CRC holds",
            )
        finally:
            self.client.timeout_s = saved_timeout
        restart = self.restart()
        source = self.coef_source(SAVED_UNCHECKED)
        if source != "E":
            raise UploadError(f"after the reset {self.name} runs coef_source {source}, not E{self.reported(restart)}")
        if self.wait(lambda frame: frame.type == "IMU", IMU_FRAME_WAIT_S, since=restart) is None:
            raise UploadError(
                f"no IMU frame from {self.name} within {IMU_FRAME_WAIT_S:g} s after the reset"
                f"{self.reported(restart)}; ICF says coef_source E"
            )
        after_reset = {
            (s, a): self.read_back(s, a, table.surface(s, a), " after the reset", AFTER_RESET)
            for s in SETS
            for a in AXES
        }
        imu = [frame for frame in self.since(restart) if frame.type == "IMU"]
        wrong = sorted({frame["coef_source"] for frame in imu} - {"E"})
        if wrong:
            raise UploadError(f"after the reset {self.name} sent IMU frames with coef_source {', '.join(wrong)}, not E")
        return UploadResult(
            self.name,
            version["firmware_version"],
            table,
            CoefficientTable(read_back),
            CoefficientTable(after_reset),
            True,
            restart["reset_cause"],
            source,
            len(imu),
        )

    def command(self, what: str, frame_type: str, values: Iterable[Any] = (), consequence: str = "") -> Any:
        try:
            return self.client.command(frame_type, values)
        except CommandRefused as error:
            raise UploadError(f"{what} refused by {self.name}: {error.code} {error.detail}{consequence}") from None
        except CommandTimeout as error:
            raise UploadError(
                f"{what}: no answer from {self.name} within {error.timeout_s:g} s, "
                f"{error.attempts} attempt(s){consequence}"
            ) from None

    def hello(self) -> Frame:
        self.client.wait_for(lambda frame: True, BOOT_WAIT_S)
        try:
            answer = self.client.command("VERSION")
        except CommandTimeout:
            raise UploadError(
                f"{self.name} is silent: no answer to VERSION (is it the IMU reader, and at this baud rate?)"
            ) from None
        except CommandRefused as error:
            raise UploadError(f"VERSION refused by {self.name}: {error.code} {error.detail}") from None
        versions = [frame for frame in answer.data if frame.type == "VER"]
        if not versions:
            raise UploadError(f"{self.name} answered VERSION without a VER frame")
        version = versions[-1]
        if version["device"] != "imu_reader":
            raise UploadError(f"{self.name} is the {version['device']}, not the imu_reader")
        if version["protocol_version"] != PROTOCOL_VERSION:
            raise UploadError(
                f"{self.name} speaks protocol {version['protocol_version']}, this host "
                f"{PROTOCOL_VERSION}: update the firmware or the host"
            )
        return version

    def read_back(self, set_name: str, axis: str, sent: Surface, when: str, consequence: str) -> Surface:
        what = f"GETCOE {set_name} {axis}{when}"
        answer = self.command(what, "GETCOE", [set_name, axis], consequence)
        coe = [
            frame for frame in answer.data if frame.type == "COE" and (frame["set"], frame["axis"]) == (set_name, axis)
        ]
        if not coe:
            raise UploadError(f"{what}: {self.name} answered without its COE frame{consequence}")
        printed = Surface(*(coe[-1][term] for term in COEFFICIENT_NAMES))
        mismatch = first_mismatch(sent, printed)
        if mismatch is not None:
            raise UploadError(f"{what} read back {mismatch}{consequence}")
        return printed

    def coef_source(self, consequence: str) -> str:
        answer = self.command("STATUS", "STATUS", (), consequence)
        configs = [frame for frame in answer.data if frame.type == "ICF"]
        if not configs:
            raise UploadError(f"{self.name} answered STATUS without an ICF frame{consequence}")
        return configs[-1]["coef_source"]

    def restart(self) -> Frame:
        """RESET, and the VER of the board's restart."""
        mark = len(self.frames)
        self.command("RESET", "RESET", (), SAVED_UNCHECKED + " (reset the board, then check coef_source)")
        restart = self.wait(lambda frame: frame.type == "VER", RESTART_WAIT_S, since=mark)
        if restart is None:
            raise UploadError(
                f"{self.name} did not come back within {RESTART_WAIT_S:g} s of RESET (an old "
                "bootloader that leaves the watchdog on keeps resetting: see docs/reliability.md)" + SAVED_UNCHECKED
            )
        if restart["reset_cause"] != "COMMANDED":
            raise UploadError(
                f"after RESET {self.name} reported reset_cause {restart['reset_cause']}, not "
                f"COMMANDED{self.reported(restart)}" + SAVED_UNCHECKED
            )
        return restart

    def since(self, first: Frame | int) -> list[Frame]:
        """The unclaimed frames from `first` (a frame, or an index) on."""
        if isinstance(first, int):
            return self.frames[first:]
        return self.frames[next(i for i, frame in enumerate(self.frames) if frame is first) :]

    def wait(self, wanted: Callable[[Frame], bool], timeout_s: float, since: Frame | int) -> Frame | None:
        """A wanted frame already received from `since` on, or the next within timeout_s."""
        for frame in self.since(since):
            if wanted(frame):
                return frame
        return self.client.wait_for(wanted, timeout_s)

    def reported(self, since: Frame) -> str:
        errors = list(
            dict.fromkeys(
                f"{frame['code']} {frame['detail']}"
                for frame in self.since(since)
                if frame.type == "ERR" and frame["cmd_seq"] == -1
            )
        )
        return f" (it reported {', '.join(errors)})" if errors else ""


def format_result(result: UploadResult) -> str:
    columns = "".join(f"{term:>12}" for term in COEFFICIENT_NAMES)
    lines = [
        f"imu_reader {result.firmware_version} on {result.port}: read back equal to what was sent at "
        f"COE's {COE_SIGNIFICANT_DIGITS} significant digits",
        f"  set axis{columns}  read back  after reset",
    ]
    for set_name in SETS:
        for axis in AXES:
            values = "".join(f"{value:>12.4e}" for value in result.sent.surface(set_name, axis))
            after = "equal" if result.after_reset is not None else "-"
            lines.append(f"  {set_name}   {axis}   {values}  {'equal':<9}  {after}")
    if result.saved:
        lines.append(
            f"saved to EEPROM; after the reset ({result.reset_cause}) the board runs them: coef_source "
            f"{result.coef_source} in ICF and in {result.imu_frames_checked} IMU frames"
        )
    else:
        lines.append(
            f"in RAM only (coef_source {result.coef_source}): a reset or power cycle restores the "
            "EEPROM's coefficients; upload without --no-save to keep them"
        )
    return "\n".join(lines)
