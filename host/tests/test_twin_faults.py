"""The twin's fault registry (thermotilt.twin.faults): every fault the model
file and --fault accept is one registered class that acts on the board it
names, and undoes what it did when it ends, but for a hang, which only the
watchdog ends. Against stand-in boards: what the firmware then does is
test_simulate.py's and test_safety.py's."""

from types import SimpleNamespace

import pytest

from thermotilt.physics import FAULT_NAMES, ModelError, parse_fault
from thermotilt.twin.faults import FAULTS


class StandInBoard:
    """Records the state each fault-setting call leaves."""

    def __init__(self):
        self.state = {}

    def set_lsm9ds0_fault(self, mode):
        self.state["lsm9ds0"] = mode

    def wire_lsm9ds0_data_ready(self, wired):
        self.state["data_ready_wired"] = wired

    def set_adc_fault(self, channel, kind):
        self.state[f"adc{channel}"] = kind

    def set_l298n_disconnected(self, disconnected):
        self.state["l298n_disconnected"] = disconnected

    def hang(self):
        self.state["hung"] = True

    def set_uart_corruption(self, probability, seed):
        self.state["uart_corruption"] = (probability, seed)


def stand_in_twin():
    return SimpleNamespace(
        boards={"imu_reader": StandInBoard(), "thermal_chamber": StandInBoard()},
        chamber=SimpleNamespace(inner_thermistor_detached=False, heatsink_failed=False),
        peltier_reversed=False,
        seed=7,
    )


def what_changes(twin):
    return {name: dict(board.state) for name, board in twin.boards.items()} | {
        "chamber": vars(twin.chamber).copy(),
        "peltier_reversed": twin.peltier_reversed,
    }


NEUTRAL = {
    "lsm9ds0": "none",
    "data_ready_wired": True,
    "adc0": "none",
    "adc1": "none",
    "l298n_disconnected": False,
    "uart_corruption": (0.0, 7),
}

# What each fault changes while active (board -> state, or twin attribute).
ACTIVE = {
    "sensor_absent": ("imu_reader", {"lsm9ds0": "absent"}),
    "sensor_stuck": ("imu_reader", {"lsm9ds0": "stuck"}),
    "data_ready_cut": ("imu_reader", {"data_ready_wired": False}),
    "inner_open": ("thermal_chamber", {"adc0": "open"}),
    "inner_short": ("thermal_chamber", {"adc0": "short"}),
    "outer_open": ("thermal_chamber", {"adc1": "open"}),
    "outer_short": ("thermal_chamber", {"adc1": "short"}),
    "peltier_disconnected": ("thermal_chamber", {"l298n_disconnected": True}),
    "peltier_reversed": ("peltier_reversed", True),
    "inner_detached": ("chamber", {"inner_thermistor_detached": True, "heatsink_failed": False}),
    "heatsink_failed": ("chamber", {"inner_thermistor_detached": False, "heatsink_failed": True}),
    "chamber_hang": ("thermal_chamber", {"hung": True}),
    "imu_hang": ("imu_reader", {"hung": True}),
    "imu_uart_corrupt": ("imu_reader", {"uart_corruption": (0.01, 7)}),
    "chamber_uart_corrupt": ("thermal_chamber", {"uart_corruption": (0.01, 7)}),
}


def test_the_registry_is_every_fault_name():
    assert FAULT_NAMES == tuple(FAULTS) == tuple(ACTIVE)


@pytest.mark.parametrize("name", FAULT_NAMES)
def test_each_fault_acts_on_its_board_and_ends(name):
    kind = FAULTS[name]
    rate = 0.01 if kind.takes_rate else None
    twin = stand_in_twin()
    kind.apply(twin, True, rate)
    target, changed = ACTIVE[name]
    active = what_changes(twin)
    assert active[target] == changed
    if target in twin.boards:
        assert target == kind.board
        assert all(state == {} for board, state in active.items() if board in twin.boards and board != target)
    kind.apply(twin, False, rate)
    ended = what_changes(twin)
    if name.endswith("_hang"):
        assert ended == active
    elif target in twin.boards:
        assert ended[target] == {key: NEUTRAL[key] for key in changed}
    else:
        assert ended == what_changes(stand_in_twin())


@pytest.mark.parametrize("name", FAULT_NAMES)
def test_a_rate_is_given_exactly_to_the_faults_that_take_one(name):
    if FAULTS[name].takes_rate:
        assert parse_fault(f"{name}=0.5").rate == 0.5
        with pytest.raises(ModelError, match="needs a rate"):
            parse_fault(name)
    else:
        assert parse_fault(name).rate is None
        with pytest.raises(ModelError, match="takes no rate"):
            parse_fault(f"{name}=0.5")
