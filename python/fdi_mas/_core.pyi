"""Type stubs of the extension module (the Rust side of fdi_mas)."""

from os import PathLike

class ScenarioError(ValueError):
    problems: list[tuple[str, str]]

class EngineError(RuntimeError): ...

class Scenario:
    @staticmethod
    def paper(
        *,
        attack: str = ...,
        controller: str = ...,
        duration_s: float = ...,
        seed: int = ...,
        residual: str = ...,
        clock: str = ...,
        observer_input: str = ...,
        leakage_w_per_s: float = ...,
        dead_zone_rad_s: float = ...,
        innovation_time_constant_s: float = ...,
    ) -> Scenario: ...
    @staticmethod
    def load(
        path: str | PathLike[str],
        *,
        attack: str = ...,
        controller: str = ...,
        duration_s: float = ...,
        seed: int = ...,
        residual: str = ...,
        clock: str = ...,
        observer_input: str = ...,
        leakage_w_per_s: float = ...,
        dead_zone_rad_s: float = ...,
        innovation_time_constant_s: float = ...,
    ) -> Scenario: ...
    def replace(
        self,
        *,
        attack: str = ...,
        controller: str = ...,
        duration_s: float = ...,
        seed: int = ...,
        residual: str = ...,
        clock: str = ...,
        observer_input: str = ...,
        leakage_w_per_s: float = ...,
        dead_zone_rad_s: float = ...,
        innovation_time_constant_s: float = ...,
    ) -> Scenario: ...
    @property
    def name(self) -> str: ...
    @property
    def agents(self) -> list[int]: ...
    @property
    def links(self) -> int:
        """The most joints of a robot of the team (the tick table's columns per joint)."""
    @property
    def joint_counts(self) -> dict[int, int]:
        """Each robot's joints, by id."""
    @property
    def duration_s(self) -> float: ...
    @property
    def control_period_s(self) -> float: ...
    @property
    def ticks(self) -> int: ...
    @property
    def seed(self) -> int: ...
    @property
    def residual(self) -> str: ...
    @property
    def attack(self) -> str: ...
    @property
    def controller(self) -> str: ...
    def to_toml(self) -> str: ...

class RunResult:
    @property
    def summary_json(self) -> str: ...
    @property
    def digest(self) -> str: ...
    @property
    def table(self) -> str: ...
    @property
    def columns(self) -> list[tuple[str, str, bytes]] | None: ...
    @property
    def run_dir(self) -> str | None: ...
    @property
    def warnings(self) -> list[str]: ...

def run(scenario: Scenario, ticks: bool = True) -> RunResult: ...
def open_run(run_dir: str | PathLike[str], ticks: bool = True) -> RunResult: ...
def presets() -> list[str]: ...
def detectors() -> list[str]: ...
def panic_for_test() -> None: ...
def attacker_reward(
    ticks: int,
    damage: float,
    alarm_ticks: int,
    damage_weight: float,
    stealth_weight: float,
    damage_scale_rad: float,
) -> float: ...
def defender_reward(
    ticks: int,
    damage: float,
    action: list[float],
    error_scale_rad: float,
    effort_weight: float,
) -> float: ...

_Outcome = tuple[int, float, int, list[int], bool, bool, bytes, bytes]

class Episode:
    def __init__(
        self,
        scenario: Scenario,
        robots: list[int],
        channels: list[str],
        budget: list[float],
        detectors: list[str],
        decision_period: int,
        correction_budget: float = 0.0,
    ) -> None: ...
    def reset(self, scenario: Scenario | None = None) -> None: ...
    def step(self, action: bytes) -> _Outcome: ...
    def views(self) -> tuple[bytes, bytes]: ...
    def summary_json(self) -> str | None: ...
    def progress(self) -> tuple[int, int]: ...
    def shape(self) -> tuple[list[int], int, int]: ...
    def joints(self) -> tuple[list[int], list[bool]]: ...
    def close(self) -> None: ...
    @property
    def closed(self) -> bool: ...

class Batch:
    def __init__(
        self,
        scenario: Scenario,
        n: int,
        robots: list[int],
        channels: list[str],
        budget: list[float],
        detectors: list[str],
        decision_period: int,
        damage_weight: float,
        stealth_weight: float,
        damage_scale_rad: float,
        threads: int | None = None,
    ) -> None: ...
    @staticmethod
    def defender(
        scenarios: list[Scenario],
        n: int,
        correction_budget: float,
        decision_period: int,
        error_scale_rad: float,
        effort_weight: float,
        seed: int,
        vary_seed: bool,
        threads: int | None = None,
    ) -> Batch: ...
    def reset(self) -> bytes: ...
    def step(self, actions: bytes) -> tuple[bytearray, bytearray, bytearray, bytearray]: ...
    def digests(self) -> list[str | None]: ...
    def shape(self) -> tuple[list[int], int, int]: ...
    def joints(self) -> tuple[list[int], list[bool]]: ...
    def close(self) -> None: ...
    @property
    def threads(self) -> int: ...
