"""The Peltier chamber's effects and hardware: two faces of the cell as
lumped nodes ("inner", the reference face; "outer", the heatsink face) and
the room ("ambient"). "Datasheet" is the TEC1-12706's (Vmax 14.4 V, Imax
6.4 A, dTmax 66 K at Th = 300 K: Seebeck 0.048 V/K, 1.755 Ω, 0.545 W/K); the
drive is an L298N with both bridges paralleled, 4 A (ST's L298 datasheet:
2 A DC per bridge, total DC current up to 4 A)."""

from __future__ import annotations

from ..parameters import Bounds, Parameter, PerAxis
from . import ChamberTerm, HeatFlows, Section, hardware, register

HEAT_CAPACITY = Bounds(4.0, 1e5, "J/K")
HEATER_POWER = Bounds(0.0, 500.0, "W")
RESISTOR = Bounds(100.0, 1e7, "ohm")
HEATER_POWER_WHY = (
    "the TEC1-12706 pumps at most 50–60 W and dissipates 72 W at its 6.4 A maximum; "
    "the largest single-stage modules stay below a few hundred watts"
)


@hardware
class ChamberHardware(Section):
    name = "chamber"
    summary = "the inner face's heat capacity and the thermistor dividers"
    parameters = (
        Parameter(
            "inner_heat_capacity_j_per_k",
            HEAT_CAPACITY,
            400.0,
            "tuned to Figure 8: a 2 °C step reaches 90 % in ~13 s under the paper's P control "
            "with the 4 A drive (~440 g of aluminium: plate, mount, sensor board)",
            "the Peltier's own ceramic plate (40 × 40 × 0.8 mm alumina, ≈ 4.4 J/K) is the least "
            "a face carries; 100 000 J/K is ~110 kg of aluminium. The lower bound also keeps the "
            "integrator's substeps (5 % of a time constant) to a few per 10 ms step",
        ),
        Parameter(
            "supply_mv",
            Bounds(1800.0, 5500.0, "mV"),
            5000.0,
            "the Arduino's 5 V rail feeding the dividers",
            "the ATmega328P/2560 supply range",
        ),
        Parameter(
            "divider_reference_ohm",
            RESISTOR,
            100000.0,
            "paper section 3.1",
            "below 100 Ω the divider draws tens of mA and heats the NTC; above 10 MΩ the ADC's "
            "sample capacitor cannot charge between conversions",
        ),
        Parameter(
            "thermistor_r25_ohm",
            RESISTOR,
            100000.0,
            "paper: CLW1064 100 kΩ",
            "catalogue NTCs run from about 100 Ω to 1 MΩ at 25 °C",
        ),
        Parameter(
            "thermistor_beta_k",
            Bounds(1000.0, 10000.0, "K"),
            3950.0,
            "paper, equation 1",
            "catalogue NTCs have β of about 2500–5000 K",
        ),
    )


@register
class PeltierPumping(ChamberTerm):
    name = "peltier_pumping"
    summary = "s·P·d pumped from the outer face into the inner one"
    parameters = (
        Parameter(
            "full_duty_w",
            HEATER_POWER,
            56.3,
            "datasheet Seebeck 0.048 V/K × the paralleled L298N's 4 A × 293 K; at Imax the "
            "same model nets the datasheet's Qmax, 56 W",
            HEATER_POWER_WHY,
        ),
    )

    def flows(self) -> HeatFlows:
        full_duty_w = self.values["full_duty_w"]

        def drive(duty: float, direction: int) -> tuple[float, float]:
            pumped_w = direction * full_duty_w * duty
            return pumped_w, -pumped_w

        return HeatFlows(drive=drive)


@register
class JouleHeating(ChamberTerm):
    name = "joule_heating"
    summary = "J·d^n dissipated in the cell, a share f to the inner face"
    parameters = (
        Parameter(
            "full_duty_w",
            HEATER_POWER,
            28.1,
            "(4 A)² × 1.755 Ω (datasheet)",
            HEATER_POWER_WHY,
        ),
        Parameter(
            "exponent",
            Bounds(1.0, 2.0),
            2.0,
            "2 for a current proportional to duty (a filtered drive); on/off PWM would give 1",
            "1 for unfiltered on/off PWM, 2 for a current proportional to duty",
        ),
        Parameter(
            "inner_fraction",
            Bounds(0.0, 1.0),
            0.5,
            "the standard TEC model: half",
            "a share of the heat",
        ),
    )

    def flows(self) -> HeatFlows:
        full_duty_w = self.values["full_duty_w"]
        exponent = self.values["exponent"]
        inner_fraction = self.values["inner_fraction"]
        outer_fraction = 1.0 - inner_fraction

        def drive(duty: float, direction: int) -> tuple[float, float]:
            joule_w = full_duty_w * duty**exponent if duty > 0.0 else 0.0
            return joule_w * inner_fraction, joule_w * outer_fraction

        return HeatFlows(drive=drive)


@register
class AmbientLeak(ChamberTerm):
    name = "ambient_leak"
    summary = "G_a from the inner face to ambient"
    parameters = (
        Parameter(
            "conductance_w_per_k",
            Bounds(0.0, 10.0, "W/K"),
            0.1,
            "assumed: 2 cm of polystyrene (0.035 W/mK) over ~0.06 m²",
            "0 is perfect insulation; 10 W/K is a 0.1 m² face in a fan's draught (~100 W/m²K)",
        ),
    )

    def flows(self) -> HeatFlows:
        return HeatFlows(conductances={("inner", "ambient"): self.values["conductance_w_per_k"]})


@register
class Heatsink(ChamberTerm):
    name = "heatsink"
    summary = (
        "the outer face as a node: C_o, cell conductance K, G_s to ambient. Disabled: an ideal "
        "heatsink, the outer face at ambient; K still couples the faces"
    )
    parameters = (
        Parameter(
            "heat_capacity_j_per_k",
            HEAT_CAPACITY,
            150.0,
            "assumed: ~170 g of aluminium",
            "as the inner face: at least the outer ceramic plate",
        ),
        Parameter(
            "inner_conductance_w_per_k",
            Bounds(0.0, 10.0, "W/K"),
            0.545,
            "datasheet",
            "the cell's conduction, 0.545 W/K for the TEC1-12706; 10 W/K is beyond the largest single-stage modules",
        ),
        Parameter(
            "ambient_conductance_w_per_k",
            Bounds(0.0, 50.0, "W/K"),
            5.0,
            "assumed: a fan-cooled heatsink of 0.2 K/W (forced air: 3–10 W/K); a passive one "
            "(~0.5 K/W) cannot take the ~75 W the cell rejects at full cooling",
            "2 W/K for a passive finned heatsink (0.5 K/W), 10 W/K fan-cooled, 50 W/K a "
            "liquid-cooled cold plate (0.02 K/W)",
        ),
    )

    def flows(self) -> HeatFlows:
        return HeatFlows(
            nodes={"outer": self.values["heat_capacity_j_per_k"]},
            conductances={
                **self.flows_when_off().conductances,
                ("outer", "ambient"): self.values["ambient_conductance_w_per_k"],
            },
        )

    def flows_when_off(self) -> HeatFlows:
        # Conduction through the cell stays when the heatsink is ideal.
        return HeatFlows(conductances={("inner", "outer"): self.values["inner_conductance_w_per_k"]})


@register
class ThermistorLag(ChamberTerm):
    name = "thermistor_lag"
    summary = "first-order lag of both thermistors behind their faces"
    parameters = (
        Parameter(
            "time_constant_s",
            Bounds(0.0, 600.0, "s", low_exclusive=True),
            2.5,
            "paper: response < 5 s; tuned with the inner heat capacity to Figure 8",
            "any positive lag is harmless to the model (a film sensor responds in milliseconds); "
            "a bead in still air takes seconds, 10 minutes would be a probe in a massive well",
        ),
    )

    def thermistor_lag_s(self) -> float | None:
        return self.values["time_constant_s"] if self.enabled else None


@register
class DriveDeadZone(ChamberTerm):
    name = "drive_dead_zone"
    enabled_by_default = False
    summary = (
        "a share t of every PWM period moves no heat (the bridge's switching and the cell's "
        "current rise): the cell sees (d − t)/(1 − t), nothing below t, full duty still full"
    )
    parameters = (
        Parameter(
            "threshold_duty",
            Bounds(0.0, 0.5),
            0.02,
            "assumed: the L298N's ~2 µs switching delays are 0.1 % of the 2 ms PWM period "
            "(pin 9, 490 Hz); 2 % leaves room for a slow current rise in the cell's leads",
            "0 is an ideal bridge; a bridge losing half of every period is no longer fit to drive the cell",
        ),
    )

    def flows(self) -> HeatFlows:
        threshold = self.values["threshold_duty"]

        def seen_duty(duty: float) -> float:
            return max(0.0, (duty - threshold) / (1.0 - threshold))

        return HeatFlows(seen_duty=seen_duty)


@register
class ThermistorOffset(ChamberTerm):
    name = "thermistor_offset"
    enabled_by_default = False
    summary = "each thermistor reads its face this much warmer (a part or divider off nominal)"
    parameters = (
        Parameter(
            "offset_c",
            PerAxis(Bounds(-5.0, 5.0, "degC"), keys=("inner", "outer")),
            {"inner": 0.0, "outer": 0.0},
            "a candidate: 0 until discovery fits it",
            "the CLW1064's 1 % R25 and 1 % β tolerances and a 1 % divider resistor shift a "
            "reading by up to ~0.7 °C within −10…45 °C; 5 °C is a part of another β",
        ),
    )

    def reading_offsets_c(self) -> tuple[float, float] | None:
        if not self.enabled:
            return None
        offsets = self.values["offset_c"]
        return float(offsets["inner"]), float(offsets["outer"])
