"""``thermotilt upload FIT_DIR --port PORT``: a fit's surfaces into the IMU
reader, each step checked before the next (docs/calibration.md, "Uploading"),
and ``thermotilt assign-id ID --port PORT``: the sensor ID a board carries.

1. The fit: FIT_DIR/coefficients.json (``thermotilt fit``): the table as
   float32, the firmware's type (a surface the fit did not make, Z or an
   axis not fitted, is zero, as in coefficients.bin), the sensor ID it was
   fitted for ("" none) and its calibrated domain.
2. The board: a Nano resets when its port is opened and sends VER once it
   has booted; a board that does not reset (the twin's pty) shows itself by
   any frame. Its VERSION answer must name the imu_reader and this host's
   protocol, and its ICF (STATUS) must carry the sensor ID the fit was made
   for: a fit for one sensor never goes onto another, nor a fit for none
   onto a board with an ID, nor a fit for a sensor onto a board without an
   ID (assign-id gives it one). A refusal here has written nothing.
3. Per set (W, C) and axis (X, Y, Z): SETCOE, then GETCOE, whose COE must
   equal what was sent; then per set with a domain SETDOM and GETDOM, whose
   DOM must equal it. A refusal, a silence or a mismatch stops the upload
   before SAVECOE, so the EEPROM keeps what it held (the RAM keeps the
   surfaces sent so far, coef_source U, until the board resets).
4. SAVECOE, RESET, the VER of the restart (reset_cause COMMANDED), then
   coef_source E and the sensor ID in ICF (STATUS), coef_source E in the IMU
   frames, and GETCOE and GETDOM again: the board now runs what it loaded
   from its EEPROM. Without saving, only STATUS: coef_source U.

"Equal" is to the COE frame's printed precision: the firmware writes each
coefficient with five significant digits, so a value read back is equal
when it lies within half a unit of the fifth significant digit of the
float32 that was sent (5e-5 of it at most). SETCOE itself carries the
float32 exactly (nine digits); that the saved block holds it bit for bit is
checked in the twin (host/tests/test_upload.py).
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import serial

from ..surfaces import AXES, COEFFICIENT_NAMES, SETS, ZERO_SURFACE, CoefficientTable, Surface
from ..wire.client import CommandClient, CommandRefused, CommandTimeout
from ..wire.coefficients import (
    CENTI,
    INT16_MAX,
    INT16_MIN,
    NO_DOMAIN,
    SetDomain,
    domain_from_dom_frame,
    sensor_id_problem,
)
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
# SAVECOE writes up to 188 EEPROM bytes at 3.3 ms each on the chip (~0.6 s).
SAVE_TIMEOUT_S = 2.0
FLOAT32_MAX = 3.4028234663852886e38
# FrameWriter::addScientific's default, which the COE frame uses.
COE_SIGNIFICANT_DIGITS = 5

NOTHING_WRITTEN = "; nothing written"
NOTHING_SAVED = "; nothing saved (the EEPROM holds what it held)"
SAVED_UNCHECKED = "; the coefficients are saved, but were not checked after a reset"
AFTER_RESET = "; the board runs other coefficients than were sent"


class UploadError(RuntimeError):
    """An upload that stopped: one readable line saying where and why."""


@dataclass(frozen=True)
class FitToUpload:
    """What an upload sends: the surfaces (float32), the sensor ID they were
    fitted for ("" none) and their calibrated domain per set."""

    table: CoefficientTable
    sensor_id: str = ""
    domain: Mapping[str, SetDomain] = field(default_factory=lambda: dict(NO_DOMAIN))


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
    sensor_id: str = ""
    domain: Mapping[str, SetDomain] = field(default_factory=lambda: dict(NO_DOMAIN))


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


def _range(value: Any, scale: int, what: str, path: Path) -> tuple[int, int] | None:
    """A [min, max] of coefficients.json's calibrated_domain in the block's
    units (value times scale, whole), or None for null."""
    if value is None:
        return None
    if (
        not isinstance(value, list)
        or len(value) != 2
        or not all(isinstance(bound, (int, float)) and not isinstance(bound, bool) for bound in value)
        or not all(math.isfinite(bound) for bound in value)
    ):
        raise UploadError(f"{path}: calibrated_domain {what} is {value!r}, not [min, max]")
    low, high = (round(bound * scale) for bound in value)
    if not INT16_MIN <= low <= high <= INT16_MAX:
        raise UploadError(f"{path}: calibrated_domain {what} {value!r} is not a range the board can hold")
    return low, high


def read_fit_identity(fit_dir: Path) -> tuple[str, dict[str, SetDomain]]:
    """The sensor ID and calibrated domain FIT_DIR/coefficients.json states;
    a fit from before they were written has neither ("" and no domain)."""
    path = fit_dir / "coefficients.json"
    try:
        document = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as error:
        raise UploadError(f"{path}: cannot read: {error}") from None
    if not isinstance(document, dict):
        raise UploadError(f"{path}: not a coefficients.json written by thermotilt fit")
    sensor_id = document.get("sensor_id", "")
    if not isinstance(sensor_id, str) or sensor_id_problem(sensor_id) is not None:
        raise UploadError(f"{path}: {sensor_id_problem(str(sensor_id)) or f'sensor_id {sensor_id!r} is not text'}")
    domains = document.get("calibrated_domain")
    if domains is None:
        return sensor_id, dict(NO_DOMAIN)
    try:
        domain = {}
        for set_name in SETS:
            entry = domains[set_name]
            acceleration = entry["acceleration_lsb"]
            domain[set_name] = SetDomain(
                _range(entry["temperature_c"], CENTI, f"{set_name} temperature_c", path),
                {axis: _range(acceleration[axis], 1, f"{set_name} {axis}", path) for axis in AXES},
            )
    except (KeyError, TypeError):
        raise UploadError(f"{path}: calibrated_domain is not the one thermotilt fit writes") from None
    return sensor_id, domain


def read_fit_to_upload(fit_dir: Path) -> FitToUpload:
    return FitToUpload(read_table(fit_dir), *read_fit_identity(fit_dir))


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
    fit = read_fit_to_upload(fit_dir)
    line = _open(port, baud)
    try:
        return upload_table(line, fit, save=save, name=port, fit_name=str(fit_dir))
    except (serial.SerialException, OSError) as error:
        raise UploadError(f"lost {port}: {error}") from None
    finally:
        line.close()


def upload_table(
    port: Any,
    fit: FitToUpload | CoefficientTable,
    save: bool = True,
    name: str = "the board",
    fit_name: str = "the fit",
) -> UploadResult:
    """Uploads a fit (a float32 table alone: fitted for no sensor, no
    domain) through a pyserial port or a twin Board (whose waits are then
    simulated time); raises UploadError."""
    if isinstance(fit, CoefficientTable):
        fit = FitToUpload(fit)
    return _Session(port, name).run(fit, save, fit_name)


@dataclass(frozen=True)
class AssignResult:
    port: str
    previous_id: str
    sensor_id: str
    coef_source: str
    reported: tuple[str, ...]  # the ERR frames the board reported on its own account


def assign_id(port: str, sensor_id: str, baud: int = DEFAULT_BAUD, replace: bool = False) -> AssignResult:
    """Opens PORT and gives its IMU reader the sensor ID (assign_sensor_id); raises UploadError."""
    line = _open(port, baud)
    try:
        return assign_sensor_id(line, sensor_id, replace=replace, name=port)
    except (serial.SerialException, OSError) as error:
        raise UploadError(f"lost {port}: {error}") from None
    finally:
        line.close()


def assign_sensor_id(port: Any, sensor_id: str, replace: bool = False, name: str = "the board") -> AssignResult:
    """SETID on a pyserial port or a twin Board: the board keeps the ID in
    its EEPROM, its coefficient block untouched. A board that already has
    another ID keeps it unless replace: its coefficients, fitted for that
    ID, would stop loading. Raises UploadError."""
    problem = sensor_id_problem(sensor_id)
    if problem is not None or not sensor_id:
        raise UploadError(problem or "the sensor ID is empty")
    session = _Session(port, name)
    session.hello()
    previous, source = session.identity()
    if previous == sensor_id:
        return AssignResult(name, previous, sensor_id, source, ())
    if previous and not replace:
        raise UploadError(
            f"{name} is already sensor {previous}; add --replace to make it {sensor_id} "
            f"(coefficients fitted for {previous} then stop loading); nothing written"
        )
    mark = len(session.frames)
    session.command(f"SETID {sensor_id}", "SETID", [sensor_id], "")
    assigned, source = session.identity()
    if assigned != sensor_id:
        raise UploadError(f"after SETID {sensor_id} {name} reports sensor ID {assigned or '(none)'}")
    reported = tuple(
        f"{frame['code']} {frame['detail']}"
        for frame in session.frames[mark:]
        if frame.type == "ERR" and frame["cmd_seq"] == -1
    )
    return AssignResult(name, previous, sensor_id, source, reported)


def format_assignment(result: AssignResult) -> str:
    if result.previous_id == result.sensor_id:
        return f"{result.port} is already sensor {result.sensor_id}; nothing written (coef_source {result.coef_source})"
    line = f"{result.port} is now sensor {result.sensor_id}"
    if result.previous_id:
        line += f" (was {result.previous_id})"
    if result.coef_source == "E":
        return line + "; its saved coefficients load for this ID (coef_source E)"
    if "EEPROM_SENSOR DEFAULTS" in result.reported:
        return line + (
            "; its saved coefficients were fitted for another sensor, so it runs the defaults "
            f"(coef_source {result.coef_source}) until a fit for {result.sensor_id} is uploaded"
        )
    return line + f"; it has no saved coefficients (coef_source {result.coef_source})"


class _Session:
    def __init__(self, port: Any, name: str):
        self.name = name
        # Every frame no command took: IMU and ERR frames, the VER of a boot.
        self.frames: list[Frame] = []
        self.client = CommandClient(port, on_frame=self.frames.append)

    def run(self, fit: FitToUpload, save: bool, fit_name: str) -> UploadResult:
        version = self.hello()
        self.check_identity(fit.sensor_id, fit_name)
        read_back = self.send(fit)
        if not save:
            source = self.coef_source("; the coefficients are in RAM, not saved")
            if source != "U":
                raise UploadError(f"after the upload {self.name} runs coef_source {source}, not U")
            return UploadResult(
                self.name,
                version["firmware_version"],
                fit.table,
                read_back,
                None,
                False,
                None,
                source,
                0,
                fit.sensor_id,
                fit.domain,
            )
        self.save()
        restart, source, after_reset, imu_frames = self.check_after_reset(fit)
        return UploadResult(
            self.name,
            version["firmware_version"],
            fit.table,
            read_back,
            after_reset,
            True,
            restart["reset_cause"],
            source,
            imu_frames,
            fit.sensor_id,
            fit.domain,
        )

    def send(self, fit: FitToUpload) -> CoefficientTable:
        """SETCOE and SETDOM, each read back; the surfaces as read back."""
        read_back = {}
        for set_name in SETS:
            for axis in AXES:
                surface = fit.table.surface(set_name, axis)
                self.command(f"SETCOE {set_name} {axis}", "SETCOE", [set_name, axis, *surface], NOTHING_SAVED)
                read_back[(set_name, axis)] = self.read_back(set_name, axis, surface, "", NOTHING_SAVED)
        domains = [set_name for set_name in SETS if fit.domain[set_name].temperature_centi_c is not None]
        for set_name in domains:
            domain = fit.domain[set_name]
            self.command(f"SETDOM {set_name}", "SETDOM", domain.setdom_values(set_name), NOTHING_SAVED)
            self.read_domain(set_name, domain, "", NOTHING_SAVED)
        return CoefficientTable(read_back)

    def save(self) -> None:
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

    def check_after_reset(self, fit: FitToUpload) -> tuple[Frame, str, CoefficientTable, int]:
        """The board reset and loading the saved block: its restart frame,
        coef_source, the surfaces read back and how many IMU frames came."""
        restart = self.restart()
        sensor_id, source = self.identity(SAVED_UNCHECKED)
        if source != "E":
            raise UploadError(f"after the reset {self.name} runs coef_source {source}, not E{self.reported(restart)}")
        if sensor_id != fit.sensor_id:
            raise UploadError(
                f"after the reset {self.name} reports sensor ID {sensor_id or '(none)'}, "
                f"not {fit.sensor_id or '(none)'}" + SAVED_UNCHECKED
            )
        if self.wait(lambda frame: frame.type == "IMU", IMU_FRAME_WAIT_S, since=restart) is None:
            raise UploadError(
                f"no IMU frame from {self.name} within {IMU_FRAME_WAIT_S:g} s after the reset"
                f"{self.reported(restart)}; ICF says coef_source E"
            )
        after_reset = {
            (s, a): self.read_back(s, a, fit.table.surface(s, a), " after the reset", AFTER_RESET)
            for s in SETS
            for a in AXES
        }
        for set_name in SETS:
            self.read_domain(set_name, fit.domain[set_name], " after the reset", AFTER_RESET)
        imu = [frame for frame in self.since(restart) if frame.type == "IMU"]
        wrong = sorted({frame["coef_source"] for frame in imu} - {"E"})
        if wrong:
            raise UploadError(f"after the reset {self.name} sent IMU frames with coef_source {', '.join(wrong)}, not E")
        return restart, source, CoefficientTable(after_reset), len(imu)

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

    def identity(self, consequence: str = "") -> tuple[str, str]:
        """The board's sensor ID ("" none) and coef_source, from its ICF."""
        answer = self.command("STATUS", "STATUS", (), consequence)
        configs = [frame for frame in answer.data if frame.type == "ICF"]
        if not configs:
            raise UploadError(
                f"{self.name} answered STATUS without an ICF frame that has a sensor_id (firmware before "
                f"imu_reader 0.3.0? update it){consequence}"
            )
        return configs[-1]["sensor_id"], configs[-1]["coef_source"]

    def coef_source(self, consequence: str) -> str:
        return self.identity(consequence)[1]

    def check_identity(self, fitted_for: str, fit_name: str) -> None:
        """Refuses, before anything is written, a fit made for another sensor than the board's."""
        board_id, _ = self.identity(NOTHING_WRITTEN)
        if board_id == fitted_for:
            return
        if not board_id:
            raise UploadError(
                f"{fit_name} was fitted for sensor {fitted_for}, {self.name} has no sensor ID: if it carries "
                f"sensor {fitted_for}, assign it with `thermotilt assign-id {fitted_for} --port {self.name}`, "
                f"then upload again{NOTHING_WRITTEN}"
            )
        if not fitted_for:
            raise UploadError(
                f"{fit_name} was fitted for no particular sensor, {self.name} is sensor {board_id}: if the "
                f"campaign was this sensor's, fit it again with --sensor-id {board_id}{NOTHING_WRITTEN}"
            )
        raise UploadError(
            f"{fit_name} was fitted for sensor {fitted_for}, {self.name} is sensor {board_id}{NOTHING_WRITTEN}"
        )

    def read_domain(self, set_name: str, sent: SetDomain, when: str, consequence: str) -> SetDomain:
        what = f"GETDOM {set_name}{when}"
        answer = self.command(what, "GETDOM", [set_name], consequence)
        frames = [frame for frame in answer.data if frame.type == "DOM" and frame["set"] == set_name]
        if not frames:
            raise UploadError(f"{what}: {self.name} answered without its DOM frame{consequence}")
        printed = domain_from_dom_frame(frames[-1])
        if printed != sent:
            raise UploadError(f"{what} read back {_domain_text(printed)}, sent {_domain_text(sent)}{consequence}")
        return printed

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


def _domain_text(domain: SetDomain) -> str:
    def bounds(pair: tuple[float, float] | None, unit: str) -> str:
        return f"{pair[0]:g}..{pair[1]:g}{unit}" if pair is not None else "none"

    axes = ", ".join(f"{axis} {bounds(domain.acceleration_lsb.get(axis), ' LSB')}" for axis in AXES)
    return f"T {bounds(domain.temperature_c, ' degC')}, {axes}"


def format_result(result: UploadResult) -> str:
    columns = "".join(f"{term:>12}" for term in COEFFICIENT_NAMES)
    sensor = f"sensor {result.sensor_id}" if result.sensor_id else "no sensor ID"
    lines = [
        f"imu_reader {result.firmware_version} on {result.port} ({sensor}): read back equal to what was sent at "
        f"COE's {COE_SIGNIFICANT_DIGITS} significant digits",
        f"  set axis{columns}  read back  after reset",
    ]
    for set_name in SETS:
        for axis in AXES:
            values = "".join(f"{value:>12.4e}" for value in result.sent.surface(set_name, axis))
            after = "equal" if result.after_reset is not None else "-"
            lines.append(f"  {set_name}   {axis}   {values}  {'equal':<9}  {after}")
    for set_name in SETS:
        domain = result.domain[set_name]
        if domain.temperature_centi_c is not None:
            lines.append(f"  calibrated domain {set_name}: {_domain_text(domain)}")
    if all(result.domain[set_name].temperature_centi_c is None for set_name in SETS):
        lines.append("  no calibrated domain: the IMU frames say temp_domain U")
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
