"""The ``fullpose`` command line.

Exit status: 0 success; 2 bad input or a refused call (a scenario or airframe field, an FMU
refusing a value, an unwritable output folder, a run too long for memory), printed as one
short ``fullpose: error: ...`` line naming the file, field or variable and the reason; 3 a
run that lost the vehicle (results are written, ``metrics.json`` says ``"outcome": "lost"``);
130 interrupted (Ctrl-C).  Never a Python traceback for any of these.

Commands of the packages built on the orchestrator (``fly``: the MAVLink bridge) join through
the ``fullpose.commands`` entry-point group: each entry is a function taking the argparse
subparsers and adding its command, so the CLI composes them without the orchestrator
importing them.
"""

from __future__ import annotations

import argparse
import math
import sys
from collections.abc import Iterable
from importlib.metadata import entry_points
from pathlib import Path
from typing import Any

import numpy as np

from plant import AirframeError, NativeBuildMissing, list_airframes, load_airframe

COMMANDS_GROUP = "fullpose.commands"


def _cmd_hover(args: argparse.Namespace) -> int:
    from orchestrator.sim.hover import run_hover

    summary, _ = run_hover(args.airframe, args.duration, args.out)
    print(f"airframe            {summary.airframe}")
    print(f"simulated           {summary.duration:g} s ({summary.steps} steps of 2 ms)")
    print(f"hover rotor speed   {summary.hover_omega_rad_s[0]:.3f} rad/s")
    print(f"max position drift  {summary.max_position_drift_m:.3e} m")
    print(f"max attitude drift  {summary.max_attitude_drift_rad:.3e} rad")
    print(f"real-time factor    {summary.real_time_factor:.0f}x")
    if args.out is not None:
        print(f"results             {args.out / 'hover.csv'}, {args.out / 'hover_summary.json'}")
    return 0


def _fmt(value: object, spec: str, unit: str = "") -> str:
    """A metric for printing; n/a when it could not be computed (None)."""
    if value is None or not isinstance(value, (int, float)):
        return "n/a"
    return f"{value:{spec}}{' ' + unit if unit else ''}"


def _warn(lines: Iterable[str]) -> None:
    for line in lines:
        print(f"fullpose: warning: {line}", file=sys.stderr)


STEP_LINES = 10
"""``fullpose run`` prints at most this many steps' lines (metrics.json has them all)."""


def _print_tracking(m: dict[str, Any]) -> None:
    """The run's tracking errors and, with steps of the setpoint, a line per step."""
    from orchestrator.output.step_metrics import step_line

    pos = m.get("position_error") or {}
    measured = (m.get("measured") or {}).get("position_error")
    steps = m.get("steps") or []
    against = ""  # with steps: say which reference, a step of the input is no error
    if steps:
        shaped = (m.get("errors_against") or {}).get("position") == "ctrl.pos_ref_s"
        against = " against the " + ("flown (shaped)" if shaped else "given") + " reference"
    print(f"max position error  {_fmt(pos.get('max'), '.4f', 'm')} "
          f"(RMS {_fmt(pos.get('rms'), '.4f', 'm')})"
          + ("" if measured is None else " of the true state") + against)
    if measured is not None:  # imperfect sensors: what they said, as such
        print(f"  as measured       {_fmt(measured.get('max'), '.4f', 'm')} "
              f"(RMS {_fmt(measured.get('rms'), '.4f', 'm')}), as the sensors read it")
    if any(step.get("kind") == "attitude" for step in steps):
        att = m.get("attitude_error_vs_mu_ref") or {}
        print(f"max attitude error  {_fmt(att.get('max'), '.3f', 'deg')} "
              f"(RMS {_fmt(att.get('rms'), '.3f', 'deg')}){against}")
    for step in steps[:STEP_LINES]:
        print(step_line(step))
    if len(steps) > STEP_LINES:
        print(f"... and {len(steps) - STEP_LINES} more steps in metrics.json")


def _pil_image(option: str | None, fmi: int) -> Path | None:
    """The controller image of ``--pil [IMAGE]``: the one given, or built (cached)."""
    if option is None:
        return None
    if fmi != 2:
        raise ValueError("--pil flies the controller image in place of the controller FMU "
                         "with the FMI 2.0 plant: leave out --fmi 3 (or the scenario's fmi = 3)")
    from orchestrator.pil.build import image_of

    return image_of(option)


def _print_target(on: object) -> None:
    """The instructions per sample the target counted, as time at the assumed clock."""
    if not isinstance(on, dict) or not isinstance(on.get("instructions"), dict):
        return
    from orchestrator.pil.cost import CLOCK_HZ, CPI, microseconds, period_share

    ins = on["instructions"]
    print(f"on the Cortex-M7    {ins['mean']:.0f} / {ins['p99']:.0f} / {ins['max']:.0f} "
          f"instructions per sample (mean / p99 / max): {microseconds(ins['mean']):.0f} us mean, "
          f"{100 * period_share(ins['max']):.1f} % of the period at worst "
          f"({CLOCK_HZ / 1e6:.0f} MHz, {CPI:g} cycle per instruction assumed); "
          f"stack {on['stack_bytes']} B in a sample, {on['start_stack_bytes']} B in fpc_start")


def _cmd_build_embedded(args: argparse.Namespace) -> int:
    from orchestrator.pil.build import build_embedded, default_folder

    out = args.out if args.out is not None else default_folder()
    print(f"building the controller for the Cortex-M7 (arm-none-eabi-gcc) -> {out}")
    sys.stdout.flush()
    b = build_embedded(out)
    print(f"{b.library}: {b.library_flash} B code and constants, {b.library_ram} B static data")
    print(f"{b.elf}: flash {b.memory.flash} B, RAM {b.memory.ram} B + stack "
          f"{b.memory.stack} B (the processor-in-the-loop image for QEMU's mps2-an500)")
    return 0


def _cmd_run(args: argparse.Namespace) -> int:
    from orchestrator.runner import prepare, run_scenario
    from orchestrator.sim.outcome import EXIT_LOST

    scenario = prepare(args.scenario, args.duration, args.set, airframe=args.airframe,
                       gains=args.gains)
    if args.fmi is not None:
        from dataclasses import replace

        scenario = replace(scenario, fmi=args.fmi)
    _warn(scenario.warnings)
    if args.view or args.save is not None:  # no run whose view cannot be shown or written
        from orchestrator.output.view import check_viewer

        check_viewer(display=args.view)
    out = args.out if args.out is not None else Path("results") / Path(scenario.source).stem
    fmi = "" if scenario.fmi == 2 else ", FMI 3.0"
    pil = _pil_image(args.pil, scenario.fmi)
    on = "" if pil is None else ", the controller on the emulated Cortex-M7"
    print(f"running {scenario.name} ({scenario.duration:g} s, airframe {scenario.airframe.name}, "
          f"{scenario.coupling}{fmi}{on}) -> {out}")
    sys.stdout.flush()
    try:
        output = run_scenario(scenario, out, timing=not args.no_timing, plots=not args.no_plots,
                              csv=args.csv, engine=args.engine, mcap=args.mcap, pil=pil)
    except (Exception, KeyboardInterrupt):
        kept = (out / "metrics.json").is_file()
        args.after_error = ("no results written" + (f"; the previous results in {out} are "
                                                    "untouched" if kept else ""))
        raise
    m = output.metrics
    wall = m.get("wall_time")
    _print_tracking(m)
    print(f"real-time factor    {_fmt(m.get('real_time_factor'), '.0f')}x "
          f"({_fmt(wall, '.2f', 's')} wall)")
    for line in output.paper:
        print(line)
    _print_target(m.get("controller_on"))
    print(f"wrote {out}: {', '.join(f.name for f in output.files)}")
    if args.view or args.save is not None:
        from orchestrator.output.view import replay

        rep = replay(output.result, scenario.airframe, save=args.save, spawn=args.view)
        print(f"3-D view: {rep.pose_rows} poses, {rep.series_rows} series rows in "
              f"{rep.seconds:.2f} s" + (f", wrote {args.save}" if args.save else ""))
    lost = m.get("lost")
    if m.get("outcome") == "lost" and isinstance(lost, dict):
        print(f"fullpose: vehicle lost at t = {_fmt(lost.get('time'), '.3f', 's')}: "
              f"{lost.get('reason')}; the run stopped there", file=sys.stderr)
        return EXIT_LOST
    return 0


def _cmd_view(args: argparse.Namespace) -> int:
    from orchestrator.output.plots import resolve_airframe
    from orchestrator.output.run_result import RunResult
    from orchestrator.output.view import replay
    from plant.airframe import load_airframe

    result = RunResult.read(args.results)
    if args.airframe is not None:
        airframe = load_airframe(args.airframe)  # (a wrong name: its own one-line error)
    else:
        found = resolve_airframe(result)
        if found is None:
            raise ValueError(f"{args.results}: the results do not carry or name a loadable "
                             "airframe; give it with --airframe NAME_OR_FILE")
        airframe = found
    rep = replay(result, airframe, save=args.save, spawn=args.save is None)
    print(f"{args.results}: {rep.pose_rows} poses, {rep.series_rows} series rows sent in "
          f"{rep.seconds:.2f} s" + (f"; wrote {args.save}" if args.save else " to the viewer"))
    return 0


def _cmd_scenarios(args: argparse.Namespace) -> int:
    from orchestrator.scenario.catalogue import list_scenarios

    for sc in list_scenarios():
        print(f"{sc.name:30s} {sc.duration:6g} s  {sc.airframe.name:22s} {sc.description}")
    return 0


def _cmd_check(args: argparse.Namespace) -> int:
    from orchestrator.master import CoSimulation
    from orchestrator.runner import prepare

    sc = prepare(args.file, args.duration, args.set, airframe=args.airframe, gains=args.gains)
    _warn(sc.warnings)
    # both FMUs instantiated and initialized with the scenario's values: whatever they
    # would refuse at the start of a run is reported here too
    CoSimulation(sc).initialize_only()
    print(f"{args.file}: OK ({sc.name}, {sc.duration:g} s, airframe {sc.airframe.name}; "
          "both FMUs initialize)")
    return 0


def _cmd_export_ssp(args: argparse.Namespace) -> int:
    if args.scenario is None:
        from orchestrator.export.ssp import export_ssp

        if args.duration is not None or args.set or args.gains is not None:
            raise ValueError("--duration, --set and --gains apply to a scenario: give it "
                             "with --scenario NAME_OR_FILE")
        euler0 = tuple(math.radians(x) for x in args.euler0_deg or (0.0, 0.0, 0.0))
        fmi = 2 if args.fmi is None else args.fmi
        path = export_ssp(args.output, airframe=args.airframe or "paper_hexacopter",
                          pos0=tuple(args.pos0 or (0.0, 0.0, -3.0)),
                          stop_time=10.0 if args.stop_time is None else args.stop_time,
                          euler0=euler0, fmus=args.fmus, fmi=fmi)
        print(f"wrote {path} ({_ssp_kind(fmi)})")
        return 0
    from orchestrator.runner import prepare
    from orchestrator.scenario_ssp import export_scenario_ssp

    if args.pos0 is not None or args.euler0_deg is not None:
        raise ValueError("--pos0 and --euler0-deg set a hover pose; a scenario starts at its "
                         "reference's (or its [plant] pos0 / euler0)")
    if args.stop_time is not None and args.duration is not None:
        raise ValueError("give --duration or --stop-time, not both")
    duration = args.duration if args.duration is not None else args.stop_time
    sc = prepare(args.scenario, duration, args.set, airframe=args.airframe, gains=args.gains)
    _warn(sc.warnings)
    fmi = sc.fmi if args.fmi is None else args.fmi
    path = export_scenario_ssp(args.output, sc, fmus=args.fmus, fmi=fmi)
    print(f"wrote {path} ({_ssp_kind(fmi)}): {sc.name} ({sc.duration:g} s at "
          f"{sc.step * 1e3:g} ms, airframe {sc.airframe.name}) as ScenarioSignals, "
          "MultirotorPlant and FullPoseController; a fixed-step replay matches `fullpose run` "
          "with coupling = \"jacobi\"")
    return 0


def _ssp_kind(fmi: int) -> str:
    return "SSP 2.0, the FMI 3.0 FMUs" if fmi == 3 else "SSP 1.0, the FMI 2.0 FMUs"


def _cmd_design(args: argparse.Namespace) -> int:
    from controller import design_check

    af = load_airframe(args.airframe)
    given = design_check.read_gains(args.gains) if args.gains is not None else None
    result = design_check.check(af, given)
    print("gains             " + (given.path if given else "shipped"))
    for line in result.report():
        print(line)
    if result.certified or args.no_synthesis or given is not None:
        return 0
    out = args.out if args.out is not None else Path(f"{af.name}.gains.json")
    print(f"synthesis         for {af.name}'s model set (its lag x[0.7, 1.3]; the shipped "
          "weights, performance scaled to its actuators' bandwidth)")
    sys.stdout.flush()
    gains, fresh = design_check.synthesize(af)
    design_check.write_gains(out, gains)
    print("gains             " + str(out))
    for line in fresh.report()[2:]:
        print(line)
    print(f"use them with     fullpose run SCENARIO --airframe {args.airframe} --gains {out}")
    return 0


def _cmd_airframes(args: argparse.Namespace) -> int:
    for name in list_airframes():
        af = load_airframe(name)
        kind = "tilting" if af.tilting else "fixed"
        print(f"{name:24s} {af.n_rotors} rotors, {kind:7s} {af.description}")
    return 0


def _cmd_force_set(args: argparse.Namespace) -> int:
    from controller.force_sets import hover_force
    from controller.plots_force_sets import plot_force_sets
    from controller.polytope_cache import force_sets

    af = load_airframe(args.airframe)
    afs, poly = force_sets(af)
    polygon = poly.slice_polygon(float(hover_force(af)[2]))
    print(f"airframe           {af.name}")
    print(f"S(0) facets        {len(poly.b)} (dimension {poly.dimension})")
    print(f"f_bz range         [{poly.z_range[0]:.3f}, {poly.z_range[1]:.3f}] N")
    if len(polygon):
        print(f"hover lateral max  |f_x| {np.abs(polygon[:, 0]).max():.3f} N, "
              f"|f_y| {np.abs(polygon[:, 1]).max():.3f} N (outer approximation)")
    print(f"approximation gap  {poly.gap:.3f} N ({100 * poly.relative_gap:.1f} %)")
    if args.plot is not None:
        plot_force_sets(af, args.plot, afs=afs, s0=poly)
        print(f"plot               {args.plot}")
    return 0


def _cmd_fmus(args: argparse.Namespace) -> int:
    from controller import CONTROLLER_FMU, controller_fmu
    from orchestrator.export.signals import SIGNALS_FMU, signals_fmu
    from plant import PLANT_FMU, plant_fmu

    for name, path in ((PLANT_FMU, plant_fmu), (CONTROLLER_FMU, controller_fmu),
                       (SIGNALS_FMU, signals_fmu)):
        print(f"{name:20s} {path()}")
    return 0


def _cmd_build_fmus(args: argparse.Namespace) -> int:
    from orchestrator.export.fmu_build import build_fmus
    from orchestrator.export.platforms import binary_folder, parse_platforms

    platforms = parse_platforms(args.platforms)
    version = "FMI 3.0" if args.fmi == 3 else "FMI 2.0"
    print(f"building the {version} FMUs for {', '.join(p.name for p in platforms)} (Zig, from "
          f"each FMU's sources/) -> {args.out}")
    sys.stdout.flush()
    report = build_fmus(platforms, args.out, fmi=args.fmi)
    models = sorted({m for m, _ in report.binary_sizes}, key=lambda m: m != "MultirotorPlant")
    print(f"{'platform':16s} {'binaries/':16s} {'time':>8s}  "
          + "  ".join(f"{m:>18s}" for m in models))
    for p in platforms:
        sizes = "  ".join(f"{report.binary_sizes[(m, p.name)] / 1024:15.0f} KiB" for m in models)
        print(f"{p.name:16s} {binary_folder(p, args.fmi):16s} {report.seconds[p.name]:6.1f} s  "
              f"{sizes}")
    for name, size in report.sizes().items():
        print(f"wrote {args.out / name} ({size / 1024:.0f} KiB)")
    print(f"built in {report.total_seconds:.1f} s")
    return 0


def _sweep_defaults(args: argparse.Namespace) -> None:
    """The options whose default depends on the campaign (--faults): duration, designs and
    output folder; then the checks of every option."""
    from orchestrator.sweep_faults import FAULT_DURATION

    if args.duration is None:
        args.duration = FAULT_DURATION if args.faults else 6.0
    if args.designs is None:
        args.designs = "hinf" if args.faults else "hinf,baseline"
    if args.out is None:
        args.out = Path("results") / ("sweep_faults" if args.faults else "sweep")
    if args.cases < 1 or args.duration <= 1.0:
        raise ValueError("sweep needs --cases >= 1 and --duration > 1 s")
    if not (math.isfinite(args.noise) and args.noise >= 0.0):
        raise ValueError(f"sweep --noise must be a finite factor >= 0, got {args.noise}")
    if not (math.isfinite(args.torque) and args.torque >= 0.0):
        raise ValueError(f"sweep --torque must be a finite amplitude >= 0 N m, got {args.torque}")
    if args.faults and (args.torque or args.delay):
        raise ValueError("the fault campaign takes neither a torque step amplitude nor the "
                         "delay (its loads are its own)")


def _cmd_sweep(args: argparse.Namespace) -> int:
    import time

    from orchestrator.sweep import Campaign, run_sweep
    from orchestrator.sweep_faults import run_fault_sweep

    _sweep_defaults(args)
    _warn(Campaign(args.scenario, args.airframe, args.duration).base().warnings)
    t0 = time.perf_counter()
    common: dict[str, Any] = {
        "workers": args.workers, "dask": args.dask, "noise": args.noise,
        "design_set": [d.strip() for d in args.designs.split(",") if d.strip()],
        "scenario": args.scenario, "airframe": args.airframe}
    if args.faults:
        rows = run_fault_sweep(args.cases, args.seed, args.duration, **common)
    else:
        rows = run_sweep(args.cases, args.seed, args.duration, torque=args.torque,
                         delay=args.delay, **common)
    wall = time.perf_counter() - t0
    meta = {"n": args.cases, "seed": args.seed, "duration": args.duration,
            "scenario": args.scenario, "airframe": args.airframe, "noise": args.noise,
            "torque": args.torque, "delay": args.delay, "faults": args.faults,
            "workers": args.dask or args.workers, "wall_time": wall,
            "throughput": len(rows) / wall}
    files = (_print_faults if args.faults else _print_sweep)(rows, args.out, meta)
    rate = f"{len(rows) / wall:.2f} runs/s"
    if not args.dask:  # a Dask cluster's worker count is the cluster's
        per = len(rows) / wall / max(1, args.workers)
        rate += f"; per worker {per:.2f} runs/s, {per * args.duration:.0f}x real time"
    print(f"{len(rows)} runs in {wall:.1f} s ({rate})")
    print(f"wrote               {', '.join(str(f) for f in files)}")
    return 0


def _print_sweep(rows: list[dict[str, object]], out: Path,
                 meta: dict[str, object]) -> list[Path]:
    """The disturbance campaign's files and per-design lines; the files written."""
    from orchestrator.sweep_report import summarize, write_outputs

    files = write_outputs(rows, out, meta)
    for d, s in summarize(rows).items():
        print(f"{d:9s} stable {100 * s['stable_fraction']:.0f} %  max err mean "
              f"{s['max_err_mean']:.4f} m (worst {s['max_err_worst']:.4f})  RMS mean "
              f"{s['rms_err_mean']:.4f} m  recovery mean {s['recovery_mean']:.2f} s")
    return files


def _print_faults(rows: list[dict[str, object]], out: Path,
                  meta: dict[str, object]) -> list[Path]:
    """The fault campaign's files and per-design counts; the files written."""
    from orchestrator.sweep_faults_report import fault_stats, summary_lines, write_fault_outputs

    files = write_fault_outputs(rows, out, meta)
    for d, s in fault_stats(rows).items():
        print("\n".join(summary_lines(d, s)))
    return files


GAINS_HELP = "fly with the gains of this file (fullpose design) instead of the shipped ones"


def add_vehicle_options(parser: argparse.ArgumentParser, airframe_help: str,
                        gains_help: str = GAINS_HELP) -> None:
    """``--airframe NAME_OR_FILE`` and ``--gains FILE.json``, as ``run``, ``check`` and
    ``fly`` take them."""
    parser.add_argument("--airframe", default=None, metavar="NAME_OR_FILE", help=airframe_help)
    parser.add_argument("--gains", type=Path, default=None, metavar="FILE.json", help=gains_help)


def build_parser() -> argparse.ArgumentParser:
    """The fullpose command line: every subcommand and its options."""
    parser = argparse.ArgumentParser(
        prog="fullpose",
        description="Co-simulation of over-actuated multirotors (FMI 2.0 plant and controller).",
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")

    run = sub.add_parser("run", help="run a scenario: results, metrics and the paper's figures")
    run.add_argument("scenario", help="shipped scenario name or TOML file")
    run.add_argument("--out", type=Path, default=None,
                     help="output directory (default: results/NAME)")
    run.add_argument("--duration", type=float, default=None, help="override the duration (s)")
    add_vehicle_options(run, "fly the scenario on this airframe (shipped name or TOML file) "
                             "instead of the one it names")
    run.add_argument("--set", action="append", default=[], metavar="FMU.PARAM=VALUE",
                     help="override a parameter, e.g. controller.K_pos_D[1]=3 (repeatable)")
    run.add_argument("--no-timing", action="store_true",
                     help="do not measure FMU compute times (runs become bit-reproducible)")
    run.add_argument("--no-plots", action="store_true", help="skip the PNG figures")
    run.add_argument("--csv", action="store_true",
                     help="also write results.csv (exact float64 text, ~20x the Parquet file)")
    run.add_argument("--no-csv", action="store_true", help=argparse.SUPPRESS)  # the default now
    run.add_argument("--engine", choices=("native", "python"), default="native",
                     help="step loop: C kernel (default) or the pure-Python reference")
    run.add_argument("--fmi", type=int, choices=(2, 3), default=None,
                     help="the FMUs' FMI version: 2 (default) or 3 (the same model code; "
                          "default: the scenario's `fmi`)")
    run.add_argument("--pil", nargs="?", const="build", default=None, metavar="IMAGE",
                     help="fly the controller on an emulated Cortex-M7 (QEMU mps2-an500) in "
                          "place of its FMU: processor in the loop; IMAGE: an fpc_pil.elf "
                          "(default: built by `fullpose build-embedded`)")
    run.set_defaults(func=_cmd_run)

    run.add_argument("--mcap", action="store_true",
                     help="also write results.mcap (opens in Foxglove and PlotJuggler)")
    run.add_argument("--view", action="store_true",
                     help="open the 3-D view (Rerun) of the run: pip install 'fullpose[view]'")
    run.add_argument("--save", type=Path, default=None, metavar="FILE.rrd",
                     help="write the 3-D view as a Rerun recording")

    view = sub.add_parser("view", help="replay a finished run in 3-D (Rerun), from its results")
    view.add_argument("results", type=Path, help="results folder or results file")
    view.add_argument("--save", type=Path, default=None, metavar="FILE.rrd",
                      help="write a Rerun recording instead of opening the viewer")
    view.add_argument("--airframe", default=None,
                      help="airframe name or file (default: the one the results carry)")
    view.set_defaults(func=_cmd_view)

    scen = sub.add_parser("scenarios", help="list the shipped scenarios")
    scen.set_defaults(func=_cmd_scenarios)

    check = sub.add_parser("check", help="validate a scenario file and initialize both FMUs "
                                         "with its values (steps nothing)")
    check.add_argument("file", help="scenario TOML file or shipped name")
    check.add_argument("--duration", type=float, default=None, help="override the duration (s)")
    add_vehicle_options(check, "check it on this airframe instead of the one it names",
                        "with the gains of this file, as for run")
    check.add_argument("--set", action="append", default=[], metavar="FMU.PARAM=VALUE",
                       help="override a parameter, as for run (repeatable)")
    check.set_defaults(func=_cmd_check)

    ssp = sub.add_parser("export-ssp", help="export the closed loop, hovering or flying a "
                                            "scenario, as an SSP archive for other tools")
    ssp.add_argument("output", type=Path, help="archive to write (.ssp)")
    ssp.add_argument("--scenario", default=None, metavar="NAME_OR_FILE",
                     help="the scenario to replay: its references and disturbances become a "
                          "third component (ScenarioSignals); without it the loop hovers")
    add_vehicle_options(ssp, "the airframe (shipped name or TOML file; default: the "
                             "scenario's, or paper_hexacopter for a hover)",
                        "with the gains of this file, as for run (with --scenario)")
    ssp.add_argument("--duration", type=float, default=None,
                     help="with --scenario: replay only this long (s)")
    ssp.add_argument("--set", action="append", default=[], metavar="FMU.PARAM=VALUE",
                     help="with --scenario: override a parameter, as for run (repeatable)")
    ssp.add_argument("--pos0", type=float, nargs=3, default=None,
                     metavar=("X", "Y", "Z"), help="hover position (m, NED; default 0 0 -3)")
    ssp.add_argument("--euler0-deg", type=float, nargs=3, default=None,
                     metavar=("ROLL", "PITCH", "YAW"),
                     help="hover attitude (deg), held by the controller: the same pose is "
                          "written to both FMUs")
    ssp.add_argument("--fmus", type=Path, default=None, metavar="DIR",
                     help="take the FMUs from this folder (e.g. what `fullpose build-fmus "
                          "--out DIR` wrote: binaries for every platform) instead of the "
                          "installed ones")
    ssp.add_argument("--stop-time", type=float, default=None,
                     help="stop time recorded in the archive (s; default 10, or the "
                          "scenario's duration)")
    ssp.add_argument("--fmi", type=int, choices=(2, 3), default=None,
                     help="2: the FMI 2.0 FMUs in an SSP 1.0 archive (default); 3: the FMI 3.0 "
                          "FMUs in an SSP 2.0 archive, vectors as array connectors (default "
                          "with --scenario: the scenario's `fmi`)")
    ssp.set_defaults(func=_cmd_export_ssp)

    hover = sub.add_parser("hover", help="simulate the plant FMU hovering at trim (open loop)")
    hover.add_argument("--airframe", default="paper_hexacopter",
                       help="shipped airframe name or TOML file (default: paper_hexacopter)")
    hover.add_argument("--duration", type=float, default=10.0, help="seconds (default: 10)")
    hover.add_argument("--out", type=Path, default=None,
                       help="directory for hover.csv and hover_summary.json")
    hover.set_defaults(func=_cmd_hover)

    design = sub.add_parser("design", help="are the gains certified for an airframe; if not, "
                                           "synthesize gains for it")
    design.add_argument("airframe", help="shipped airframe name or TOML file")
    design.add_argument("--gains", type=Path, default=None, metavar="FILE.json",
                        help="check these gains instead of the shipped ones")
    design.add_argument("--out", type=Path, default=None, metavar="FILE.json",
                        help="where a synthesis writes its gains (default: NAME.gains.json)")
    design.add_argument("--no-synthesis", action="store_true",
                        help="only check, even when the gains are not certified")
    design.set_defaults(func=_cmd_design)

    airframes = sub.add_parser("airframes", help="list the shipped airframe files")
    airframes.set_defaults(func=_cmd_airframes)

    fs = sub.add_parser("force-set", help="feasible force set S(0) of an airframe (paper Fig. 3)")
    fs.add_argument("--airframe", default="paper_hexacopter",
                    help="shipped airframe name or TOML file (default: paper_hexacopter)")
    fs.add_argument("--plot", type=Path, default=None, help="write the Fig.-3-like plot (PNG)")
    fs.set_defaults(func=_cmd_force_set)

    sw = sub.add_parser("sweep", help="Monte-Carlo robustness campaign: H-infinity vs baseline "
                                      "(--faults: the rotor-fault detector's campaign)")
    sw.add_argument("--cases", type=int, default=50, help="sampled cases (default: 50)")
    sw.add_argument("--faults", action="store_true",
                    help="the rotor-fault campaign instead: half unknown loads, half partial or "
                         "total rotor faults, the controller never told; counts false alarms "
                         "and missed detections (default designs: hinf, duration 4 s, out "
                         "results/sweep_faults)")
    sw.add_argument("--scenario", default="hover", metavar="NAME_OR_FILE",
                    help="the scenario every case flies, perturbed (default: hover)")
    sw.add_argument("--airframe", default=None, metavar="NAME_OR_FILE",
                    help="fly it on this airframe instead of the scenario's")
    sw.add_argument("--seed", type=int, default=0, help="sampling seed (default: 0)")
    sw.add_argument("--duration", type=float, default=None,
                    help="seconds per run (default: 6; --faults: 4)")
    sw.add_argument("--designs", default=None,
                    help="comma-separated: hinf, baseline, prototype, and each NAME_matched "
                         "(_matched: the controller knows the perturbed mass and inertia; "
                         "default: hinf,baseline; --faults: hinf)")
    sw.add_argument("--noise", type=float, default=1.0,
                    help="factor on the sampled sensor noise, 0 for none (default: 1)")
    sw.add_argument("--torque", type=float, default=0.0,
                    help="also a body-torque step of up to this many N m in a random direction "
                         "(default: 0, none)")
    sw.add_argument("--delay", action="store_true",
                    help="fly every case with the command one sample late (Jacobi coupling)")
    sw.add_argument("--workers", type=int, default=1, help="local processes (default: 1)")
    sw.add_argument("--dask", default=None, metavar="tcp://HOST:PORT",
                    help="run on a Dask cluster at this scheduler address")
    sw.add_argument("--out", type=Path, default=None,
                    help="output directory (default: results/sweep; --faults: "
                         "results/sweep_faults)")
    sw.set_defaults(func=_cmd_sweep)

    fmus = sub.add_parser("fmus", help="print where the installed FMUs are")
    fmus.set_defaults(func=_cmd_fmus)

    bf = sub.add_parser("build-fmus", help="build the FMUs with binaries for several platforms "
                                           "from their sources (Zig cross compiler)")
    bf.add_argument("--platforms", default="all",
                    help="all, host, or a comma list of x86_64-linux, aarch64-linux, "
                         "x86_64-windows, x86_64-darwin, aarch64-darwin (default: all)")
    bf.add_argument("--out", type=Path, required=True,
                    help="folder for the .fmu files (plant, controller, ScenarioSignals)")
    bf.add_argument("--fmi", type=int, choices=(2, 3), default=2,
                    help="the FMI 2.0 FMUs (default) or the FMI 3.0 ones (binaries/ by FMI 3.0 "
                         "platform tuples)")
    bf.set_defaults(func=_cmd_build_fmus)

    be = sub.add_parser("build-embedded", help="cross-build the controller for a Cortex-M7 "
                                               "(libfpc.a and the processor-in-the-loop image)")
    be.add_argument("--out", type=Path, default=None,
                    help="build folder (default: the user cache, as `fullpose run --pil`)")
    be.set_defaults(func=_cmd_build_embedded)
    for command in entry_points(group=COMMANDS_GROUP):
        command.load()(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Run the fullpose command: exit status 0, 2 for bad input (one line, no traceback), 3 for a
    lost vehicle."""
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.command is None:
        parser.print_help()
        return 0
    from fmpy.fmi1 import FMICallException

    try:
        return int(args.func(args))
    except (AirframeError, NativeBuildMissing, ValueError, RuntimeError, OSError,
            FMICallException) as e:
        print(f"fullpose: error: {_message(e)}", file=sys.stderr)
        status = 2
    except KeyboardInterrupt:
        print("fullpose: interrupted", file=sys.stderr)
        status = 130
    if getattr(args, "after_error", None):
        print(f"fullpose: {args.after_error}", file=sys.stderr)
    return status


def _message(e: BaseException) -> str:
    if isinstance(e, OSError) and e.filename is not None and e.strerror:
        return f"{e.filename}: {e.strerror}"
    return str(e) or type(e).__name__


if __name__ == "__main__":
    sys.exit(main())
