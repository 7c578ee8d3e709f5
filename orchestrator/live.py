"""A closed loop stepped on demand, with references set between chunks.

For callers that decide the references as they go (the MAVLink bridge): the same
FMUs, connections, coupling and step engine as a scenario run
(``orchestrator.master``), advanced a few steps at a time on a small buffer that
is rolled over, so a session can fly for hours in constant memory.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from orchestrator.fmu import FmuInstance
from orchestrator.master import (
    COUPLINGS,
    DIST_INPUTS,
    ENGINES,
    REF_INPUTS,
    _Plan,
    controller_parameters,
)
from plant import Airframe, fmu_path, load_airframe


class LiveSession:
    """``advance()`` runs ``chunk`` steps of ``step`` seconds with the references held.

    The vehicle starts hovering at trim at ``pos0``/``euler0`` with the references
    set to that pose.  ``state()`` returns the latest plant outputs and controller
    outputs by variable name.
    """

    def __init__(self, airframe: str | Airframe = "paper_hexacopter", *,
                 pos0: Sequence[float] = (0.0, 0.0, -3.0),
                 euler0: Sequence[float] = (0.0, 0.0, 0.0), step: float = 0.002, chunk: int = 5,
                 plant_parameters: Mapping[str, float | int | bool] | None = None,
                 controller_parameters_: Mapping[str, float | int | bool] | None = None,
                 coupling: str = "gauss-seidel", engine: str = "native",
                 timing: bool = False) -> None:
        if coupling not in COUPLINGS or engine not in ENGINES:
            raise ValueError(f"coupling must be one of {COUPLINGS}, engine one of {ENGINES}")
        if chunk < 1:
            raise ValueError("chunk must be at least one step")
        self.airframe = airframe if isinstance(airframe, Airframe) else load_airframe(airframe)
        self.step_size = step
        self.chunk = chunk
        self.steps_done = 0
        self.plant_inst = FmuInstance(fmu_path("MultirotorPlant"), "plant")
        self.ctrl_inst = FmuInstance(fmu_path("FullPoseController"), "controller")
        try:
            p_params: dict[str, object] = dict(self.airframe.fmu_parameters())
            for i in range(3):
                p_params[f"pos0[{i + 1}]"] = float(pos0[i])
                p_params[f"euler0[{i + 1}]"] = float(euler0[i])
            p_params["timing"] = timing
            p_params.update(plant_parameters or {})
            c_params: dict[str, object] = dict(controller_parameters(self.airframe,
                                                                     self.ctrl_inst))
            c_params["timing"] = timing
            c_params.update(controller_parameters_ or {})
            self.reference = np.concatenate([np.asarray(pos0, float), np.asarray(euler0, float),
                                             np.zeros(9), np.ones(8)])  # + rotor_health
            self.plan = _Plan.build(self.plant_inst, self.ctrl_inst, chunk + 1, p_params,
                                    c_params, self.reference)
            widths = [len(self.plant_inst.expand(g)) for g in DIST_INPUTS]
            self.disturbance = np.zeros(sum(widths))
            self.disturbance[-widths[-1]:] = 1.0  # rotor efficiencies
            jacobi = coupling == "jacobi"
            self._runner = (self.plan.native_runner(step, jacobi) if engine == "native"
                            else self.plan.python_runner(step, jacobi))
            self._ref_slices = self._slices(self.ctrl_inst, REF_INPUTS, self.plan.c_ref)
            self._dist_slices = self._slices(self.plant_inst, DIST_INPUTS, self.plan.c_dist)
            # controller outputs before the first step: its initial ones (spare row)
            self._last_ctrl_row = self.plan.rows
        except Exception:
            self.close()
            raise

    @staticmethod
    def _slices(inst: FmuInstance, groups: Sequence[str], first: int) -> dict[str, slice]:
        out, col = {}, 0
        for g in groups:
            width = len(inst.expand(g))
            out[g] = slice(col, col + width)
            col += width
        return out

    # -- inputs --------------------------------------------------------------

    def set_reference(self, **values: Sequence[float]) -> None:
        """Any of ``pos_ref``, ``euler_ref``, ``vel_ref``, ``acc_ref``, ``euler_rate_ref``
        (3 values) and ``rotor_health`` (8 values, 0..1: what the controller knows)."""
        for name, value in values.items():
            if name not in self._ref_slices:
                raise KeyError(f"unknown reference {name!r} (one of {', '.join(REF_INPUTS)})")
            sl = self._ref_slices[name]
            v = np.asarray(value, dtype=float)
            if v.shape != (sl.stop - sl.start,) or not np.all(np.isfinite(v)):
                raise ValueError(f"{name} must be {sl.stop - sl.start} finite numbers, "
                                 f"got {value!r}")
            self.reference[sl] = v

    def set_disturbance(self, **values: Sequence[float]) -> None:
        """Any of ``f_d``, ``tau_d``, ``a_d`` (3 values) and ``efficiency`` (8)."""
        for name, value in values.items():
            if name not in self._dist_slices:
                raise KeyError(f"unknown disturbance {name!r} (one of {', '.join(DIST_INPUTS)})")
            sl = self._dist_slices[name]
            v = np.asarray(value, dtype=float)
            if v.shape != (sl.stop - sl.start,) or not np.all(np.isfinite(v)):
                raise ValueError(f"{name} must be {sl.stop - sl.start} finite numbers")
            self.disturbance[sl] = v

    def set_controller_parameter(self, name: str, value: float | int | bool) -> None:
        """A tunable controller parameter, applied from the next step on.

        The FMU validates it at the next step; an invalid value stops the session, so
        callers should range-check first (the FMU's variable descriptions say what
        is valid)."""
        var = self.ctrl_inst.variables.get(name)
        if var is None or var.causality != "parameter" or var.variability != "tunable":
            raise KeyError(f"{name!r} is not a tunable parameter of the controller")
        self.ctrl_inst.set(name, value)

    # -- stepping ------------------------------------------------------------

    def advance(self, steps: int | None = None) -> None:
        """Run ``steps`` (default ``chunk``, at most ``chunk``) steps with inputs held."""
        n = self.chunk if steps is None else steps
        if not 1 <= n <= self.chunk:
            raise ValueError(f"steps must be in 1..{self.chunk}")
        plan, data = self.plan, self.plan.data
        h = self.step_size
        data[:n, 0] = self.time + np.arange(n) * h
        data[:n, plan.c_ref:plan.c_plant] = self.reference
        data[:n, plan.c_dist:plan.c_ctrl] = self.disturbance
        self._runner(0, n, self.time)
        # roll over: y at the new time becomes row 0; u_{n-1} the Jacobi spare row
        data[0, plan.c_plant:plan.c_dist] = data[n, plan.c_plant:plan.c_dist]
        n_pint = len(plan.p_ints)
        plan.ints[0, :n_pint] = plan.ints[n, :n_pint]
        data[plan.rows, plan.c_ctrl:] = data[n - 1, plan.c_ctrl:]
        plan.ints[plan.rows, n_pint:] = plan.ints[n - 1, n_pint:]
        self._last_ctrl_row = plan.rows
        self.steps_done += n

    @property
    def time(self) -> float:
        """Simulated time of the latest plant outputs (s)."""
        return self.steps_done * self.step_size

    def state(self) -> dict[str, dict[str, np.ndarray]]:
        """Latest outputs by FMU and variable group: ``state()["plant"]["pos"]`` (at
        ``time``), ``state()["ctrl"]["mu_c"]`` (the controller's latest answer)."""
        plan = self.plan
        rows = {"plant": (plan.data[0], plan.ints[0]),
                "ctrl": (plan.data[self._last_ctrl_row], plan.ints[self._last_ctrl_row])}
        out: dict[str, dict[str, list[float]]] = {"plant": {}, "ctrl": {}}
        for i, name in enumerate(plan.plant_order):
            out["plant"].setdefault(name.split("[")[0], []).append(float(rows["plant"][0][
                plan.c_plant + i]))
        for i, name in enumerate(plan.ctrl_order):
            out["ctrl"].setdefault(name.split("[")[0], []).append(float(rows["ctrl"][0][
                plan.c_ctrl + i]))
        for i, column in enumerate(plan.int_columns):
            fmu, name = column.split(".", 1)
            out[fmu].setdefault(name.split("[")[0], []).append(float(rows[fmu][1][i]))
        return {fmu: {k: np.array(v) for k, v in d.items()} for fmu, d in out.items()}

    def close(self) -> None:
        for inst in (getattr(self, "plant_inst", None), getattr(self, "ctrl_inst", None)):
            if inst is not None:
                inst.close()

    def __enter__(self) -> LiveSession:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
