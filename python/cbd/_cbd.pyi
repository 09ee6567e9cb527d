"""Type stubs of cbd's native module (cbd._cbd); every name is re-exported by ``cbd``."""

import os
from typing import Any, Optional, Sequence, Tuple, Union

import numpy as np
import numpy.typing as npt

__version__: str

Array = npt.NDArray[np.float64]
PathLike = Union[str, "os.PathLike[str]"]
Data = Union[PathLike, Tuple[Array, Array]]
Option = Union[bool, int, float, str, None, Sequence[Union[int, float, str]]]

class CbdError(ValueError):
    """A cbd failure, with the message the ``cbd`` command prints (file, line, column or field
    named; in arrays, ``(q, y) row r``)."""

class ModelFile:
    """A model file (TOML: DH table, URDF chain or planar arm; units; CSV columns), read and checked."""

    @staticmethod
    def load(path: PathLike) -> "ModelFile":
        """Reads and checks a model file; raises CbdError naming the file and the faulty field."""
    @property
    def path(self) -> str: ...
    @property
    def name(self) -> Optional[str]: ...
    @property
    def joint_names(self) -> list[str]:
        """The URDF's joint names, or q1 … qn."""
    @property
    def n_joints(self) -> int: ...
    @property
    def task_dim(self) -> int:
        """Coordinates per point: 3, or 2 for a planar arm."""
    @property
    def length_unit(self) -> str:
        """The model's length unit: every length of a fitted model is in it."""
    @property
    def joint_columns(self) -> list[str]:
        """What ``q`` holds, column by column (``[measurements] joints``)."""
    @property
    def position_columns(self) -> list[str]:
        """What ``y`` holds: positions (per tool point), or a pose's position then orientation."""
    def to_model(self, q: Array, y: Optional[Array] = None) -> Tuple[Array, Array]:
        """Rows in the columns' units → the model's (radians, the model's length unit, joint map
        and planar frame applied, a pose read as its tool points), by the CSV import's own row code:
        ``(q, y)``, one row per (pose, tool point). With ``y=None`` the joints alone."""

class Model:
    """A calibrated model: the blob ``cbd fit`` writes, evaluated by the runtime. Units: a model
    from ``fit(model_file, …)`` or loaded with a model file takes and returns arrays in that file's
    column units, as ``cbd fit``'s CSV holds them (degrees and mm for examples/ur5/ur5.toml; a planar
    frame's base, yaw and offsets applied); a blob alone is in its own units: joints in radians
    (prismatic: the length unit) in the model's order, positions in its length unit."""

    @staticmethod
    def from_bytes(data: bytes, model: Optional[ModelFile] = None) -> "Model":
        """A model from blob bytes, checked as ``cbd eval`` checks a blob file; with ``model``
        (checked to fit the blob) arrays are in its column units, else in the blob's (radians)."""
    @staticmethod
    def load(path: PathLike, model: Optional[ModelFile] = None) -> "Model":
        """Reads a blob file (``cbd fit --out``); with ``model`` (checked to fit the blob) arrays
        are in its column units, else in the blob's (radians, the model's length unit)."""
    @property
    def units(self) -> str:
        """The units of every array in and out: the model file's columns', or the blob's own."""
    def to_bytes(self) -> bytes:
        """The blob: what the runtime, the C library and the firmware load."""
    def save(self, path: PathLike) -> None:
        """Writes the blob to ``path`` atomically."""
    @property
    def report(self) -> Optional[dict[str, Any]]:
        """The fit's report (``cbd fit --json``); None for a model read from a blob."""
    @property
    def n_joints(self) -> int: ...
    @property
    def task_dim(self) -> int: ...
    @property
    def tool_point_count(self) -> int: ...
    def evaluate(self, q: Array, jacobian: bool = False, point: int = 0) -> Union[Array, Tuple[Array, Array]]:
        """Calibrated positions (n, task_dim) of tool point ``point`` at each row of ``q`` (n,
        joints); with ``jacobian=True`` also the exact Jacobians (n, task_dim, joints). ``q`` in the
        model file's joint column units (degrees for the UR5 example), positions in its length unit
        (``Model.units``); a blob alone: radians and the model's length unit, bit for bit the runtime's."""
    def evaluate_pose(self, q: Array, jacobian: bool = False) -> Tuple[Array, ...]:
        """The calibrated tool frame (3 or more tool points): ``(origins (n, 3), rotations (n, 3, 3))``,
        with ``jacobian=True`` also (n, 6, joints). Units as ``evaluate``'s (origins in the length
        unit of the model file's columns; rotations dimensionless)."""
    def compensate(self, targets: Array, seeds: Optional[Array] = None, iterations: int = 8) -> Tuple[Array, list[str]]:
        """Joint commands (n, joints) putting the calibrated tool at each target (n, task_dim), as
        ``cbd compensate``, and a flag per row (``ok``, or ``not_reached``/``outside_limits``/``singular``/
        ``extrapolating`` joined by ``+``). Targets in the model file's length unit and frame, seeds
        and commands in its joint column units (``Model.units``); a blob alone: the model's length
        unit and radians."""

def fit(model: Optional[ModelFile], q: Array, y: Array, **options: Option) -> Model:
    """Fits a calibrated model, as ``cbd fit`` on a CSV of these columns: ``q`` (n, joints) and
    ``y`` (n, ·) in the model file's column units (``model=None``: the built-in RR arm, radians
    and metres); the model returned takes and returns arrays in the same units. ``options``
    are the command's arguments by the flags' names, each of the flag's type (``dh_first=True``,
    ``max_rows=500``, ``sigma=1e-3``, …; ``None`` is the default; an unknown keyword or a wrong type
    raises CbdError naming it). The arrays become measurements in memory, by the CSV import's own
    conversion and checks. The GIL is released while it runs; progress goes to the ``cbd`` logger."""

def compare(model: ModelFile, train: Data, test: Data, plots: Optional[PathLike] = None, **options: Option) -> dict[str, Any]:
    """Every method side by side (the face's ``compare``, the one ``cbd compare`` calls, in memory); its JSON value as a dict."""

def diagnose(
    model: Optional[ModelFile],
    data: Data,
    test: Optional[Data] = None,
    plots: Optional[PathLike] = None,
    write_model: Optional[PathLike] = None,
    **options: Option,
) -> dict[str, Any]:
    """Traces the residual to physical effects (the face's ``diagnose``, the one ``cbd diagnose`` calls, in memory); its JSON value as a dict."""

def check(model: Optional[ModelFile], blob: Union[Model, PathLike], data: Data, alpha: float = 0.01, register: bool = False) -> dict[str, Any]:
    """Does a calibration still hold (the face's ``check``, the one ``cbd check`` calls, in memory): fresh poses against the blob's own predictive distribution; its JSON value as a dict (``verdict``, ``p_value``, …)."""

def simulate(poses: Optional[PathLike] = None, **options: Option) -> Tuple[Array, Array]:
    """Simulated measurements (``cbd simulate``'s flags by name; ``poses`` a CSV of poses to measure at): ``(q, y)``, the rows the command's CSV holds."""
