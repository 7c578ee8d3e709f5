"""A closed loop stepped on demand, with references set between chunks.

For callers that decide the references as they go (the MAVLink bridge): the same
FMUs, connections, coupling and step engine as a scenario run
(``orchestrator.master``), advanced a few steps at a time on a small buffer that
is rolled over, so a session can fly for hours in constant memory.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from controller import controller_fmu
from orchestrator.sim.engine import (
    COUPLINGS,
    DIST_INPUTS,
    ENGINES,
    REF_INPUTS,
    Connections,
    Recording,
    make_engine,
)
from orchestrator.sim.fmu import FmuInstance
from orchestrator.sim.start_values import Pose, resting_on_ground, start_values
from plant import Airframe, load_airframe, plant_fmu


class LiveSession:
    """``advance()`` runs ``chunk`` steps of ``step`` seconds with the references held.

    The vehicle starts hovering at trim at ``pos0``/``euler0`` with the references
    set to that pose; with ``ground``, resting level on its landing gear on the ground below
    ``pos0`` (heading ``euler0[2]``), rotors stopped, the controller disarmed (``pos0``: the
    pose it starts at).  ``state()`` returns the latest plant outputs and controller
    outputs by variable name.  ``controller``: an instance in place of the controller FMU
    (the controller image on the emulated Cortex-M7), closed with the session.
    """

    def __init__(self, airframe: str | Airframe = "paper_hexacopter", *,
                 pos0: Sequence[float] = (0.0, 0.0, -3.0),
                 euler0: Sequence[float] = (0.0, 0.0, 0.0), step: float = 0.002, chunk: int = 5,
                 plant_parameters: Mapping[str, float | int | bool] | None = None,
                 controller_parameters_: Mapping[str, float | int | bool] | None = None,
                 coupling: str = "gauss-seidel", engine: str = "native",
                 timing: bool = False, ground: bool = False,
                 controller: FmuInstance | None = None) -> None:
        if coupling not in COUPLINGS or engine not in ENGINES:
            raise ValueError(f"coupling must be one of {COUPLINGS}, engine one of {ENGINES}")
        if chunk < 1:
            raise ValueError("chunk must be at least one step")
        self.airframe = airframe if isinstance(airframe, Airframe) else load_airframe(airframe)
        self.step_size = step
        self.chunk = chunk
        self.steps_done = 0
        try:
            self.plant_inst = FmuInstance(plant_fmu(), "plant")
        except BaseException:
            if controller is not None:
                controller.close()
            raise
        # the controller FMU, or an instance in its place the session then owns (the
        # controller image on the emulated Cortex-M7: orchestrator.pil)
        self.ctrl_inst = (controller if controller is not None
                          else FmuInstance(controller_fmu(), "controller"))
        try:
            pose = Pose.of(pos0, euler0)
            plant_over: dict[str, float | int | bool] = {}
            ctrl_over: dict[str, float | int | bool] = {}
            if ground:  # resting on the gear below pos0, rotors stopped, disarmed
                ground_z = float((plant_parameters or {}).get("ground_z", 0.0))
                pose, plant_over = resting_on_ground(self.airframe, pos0, euler0[2], ground_z)
                ctrl_over["armed"] = False
            pos0, euler0 = pose.pos, pose.euler
            self.pos0 = np.array(pos0, float)
            start = start_values(self.airframe, pose, timing=timing,
                                 plant_overrides={**plant_over, **(plant_parameters or {})},
                                 controller_overrides={**ctrl_over,
                                                       **(controller_parameters_ or {})})
            conn = Connections.closed_loop(self.plant_inst, self.ctrl_inst)
            self.rec = Recording(conn, chunk + 1)
            self.engine = make_engine(engine, self.plant_inst, self.ctrl_inst, conn, self.rec,
                                      step, coupling)
            self.reference = np.concatenate([np.asarray(pos0, float), np.asarray(euler0, float),
                                             np.zeros(9), np.ones(8)])  # + rotor_health
            self.engine.initialize(start.plant, start.controller, self.reference)
            self.disturbance = np.zeros(self.rec.dist.shape[1])
            self.disturbance[-len(conn.dist[-1]):] = 1.0  # rotor efficiencies
            self._ref_slices = self._slices(conn.ref, REF_INPUTS)
            self._dist_slices = self._slices(conn.dist, DIST_INPUTS)
            # controller outputs before the first step: its initial ones (spare row)
            self._last_ctrl_row = self.rec.spare
            self._group_index: dict[str, list[tuple[str, int, np.ndarray]]] | None = None
        except Exception:
            self.close()
            raise

    @staticmethod
    def _slices(blocks: Sequence[Sequence[str]], groups: Sequence[str]) -> dict[str, slice]:
        out, col = {}, 0
        for g, names in zip(groups, blocks, strict=True):
            out[g] = slice(col, col + len(names))
            col += len(names)
        return out

    # -- inputs --------------------------------------------------------------

    def set_reference(self, **values: Sequence[float] | np.ndarray) -> None:
        """Any of ``pos_ref``, ``euler_ref``, ``vel_ref``, ``acc_ref``, ``euler_rate_ref``
        (3 values) and ``rotor_health`` (8 values, 0..1: what the controller knows)."""
        _assign(self.reference, self._ref_slices, "reference", values)

    def set_disturbance(self, **values: Sequence[float] | np.ndarray) -> None:
        """Any of ``f_d``, ``tau_d``, ``a_d`` (3 values) and ``efficiency`` (8)."""
        _assign(self.disturbance, self._dist_slices, "disturbance", values)

    def set_controller_parameter(self, name: str, value: float | int | bool) -> None:
        """A tunable controller parameter, applied from the next step on.

        The FMU validates it at the next step; an invalid value stops the session, so
        callers should range-check first (the FMU's variable descriptions say what
        is valid)."""
        var = self.ctrl_inst.variables.get(name)
        if var is None or var.causality != "parameter" or var.variability != "tunable":
            raise KeyError(f"{name!r} is not a tunable parameter of the controller")
        self.ctrl_inst.set(name, value)

    def set_armed(self, armed: bool) -> None:
        """The controller's ``armed`` input from the next step on (disarmed: the rotors
        stop; armed: they may spin, idling while landed with the reference not above)."""
        self.ctrl_inst.set("armed", bool(armed))

    # -- stepping ------------------------------------------------------------

    def advance(self, steps: int | None = None) -> None:
        """Run ``steps`` (default ``chunk``, at most ``chunk``) steps with inputs held."""
        n = self.chunk if steps is None else steps
        if not 1 <= n <= self.chunk:
            raise ValueError(f"steps must be in 1..{self.chunk}")
        rec = self.rec
        h = self.step_size
        rec.time[:n] = self.time + np.arange(n) * h
        rec.ref[:n] = self.reference
        rec.dist[:n] = self.disturbance
        self.engine.steps(0, n, self.time)
        # roll over: y at the new time becomes row 0; u_{n-1} the Jacobi spare row
        rec.plant[0] = rec.plant[n]
        rec.int_block("plant")[0] = rec.int_block("plant")[n]
        rec.ctrl[rec.spare] = rec.ctrl[n - 1]
        rec.ints[rec.spare, rec.int_blocks["plant"].stop:] = \
            rec.ints[n - 1, rec.int_blocks["plant"].stop:]
        self._last_ctrl_row = rec.spare
        self.steps_done += n

    @property
    def time(self) -> float:
        """Simulated time of the latest plant outputs (s)."""
        return self.steps_done * self.step_size

    def state(self) -> dict[str, dict[str, np.ndarray]]:
        """Latest outputs by FMU and variable group: ``state()["plant"]["pos"]`` (at
        ``time``), ``state()["ctrl"]["mu_c"]`` (the controller's latest answer)."""
        rec = self.rec
        rows = {"plant": (rec.plant[0], rec.ints[0]),
                "ctrl": (rec.ctrl[self._last_ctrl_row], rec.ints[self._last_ctrl_row])}
        return {fmu: {name: rows[fmu][kind][idx].astype(float)
                      for name, kind, idx in self._groups()[fmu]}
                for fmu in ("plant", "ctrl")}

    def _groups(self) -> dict[str, list[tuple[str, int, np.ndarray]]]:
        """Per FMU, (group name, 0: real / 1: integer columns, their indices) in output order:
        worked out once, as the columns never change."""
        if self._group_index is None:
            conn = self.engine.conn
            found: dict[str, dict[str, tuple[int, list[int]]]] = {"plant": {}, "ctrl": {}}
            for fmu, names in (("plant", conn.plant_out), ("ctrl", conn.ctrl_out)):
                for i, name in enumerate(names):
                    found[fmu].setdefault(name.split("[")[0], (0, []))[1].append(i)
            for i, column in enumerate(self.rec.int_columns):
                fmu, name = column.split(".", 1)
                found[fmu].setdefault(name.split("[")[0], (1, []))[1].append(i)
            self._group_index = {fmu: [(name, kind, np.array(idx)) for name, (kind, idx)
                                       in groups.items()] for fmu, groups in found.items()}
        return self._group_index

    def close(self) -> None:
        """Free both FMU instances."""
        for inst in (getattr(self, "plant_inst", None), getattr(self, "ctrl_inst", None)):
            if inst is not None:
                inst.close()

    def __enter__(self) -> LiveSession:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _assign(target: np.ndarray, slices: Mapping[str, slice], kind: str,
            values: Mapping[str, Sequence[float] | np.ndarray]) -> None:
    """Writes each named input's values into its slice of ``target``, all checked first."""
    checked = []
    for name, value in values.items():
        if name not in slices:
            raise KeyError(f"unknown {kind} {name!r} (one of {', '.join(slices)})")
        sl = slices[name]
        v = np.asarray(value, dtype=float)
        if v.shape != (sl.stop - sl.start,) or not np.all(np.isfinite(v)):
            raise ValueError(f"{name} must be {sl.stop - sl.start} finite numbers, got {value!r}")
        checked.append((sl, v))
    for sl, v in checked:
        target[sl] = v

