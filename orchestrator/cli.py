"""The ``fullpose`` command line."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from plant import AirframeError, NativeBuildMissing, fmu_path, list_airframes, load_airframe


def _cmd_hover(args: argparse.Namespace) -> int:
    from orchestrator.hover import run_hover

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


def _cmd_airframes(args: argparse.Namespace) -> int:
    for name in list_airframes():
        af = load_airframe(name)
        kind = "tilting" if af.tilting else "fixed"
        print(f"{name:24s} {af.n_rotors} rotors, {kind:7s} {af.description}")
    return 0


def _cmd_force_set(args: argparse.Namespace) -> int:
    from controller.force_sets import feasible_force_set, hover_force
    from controller.plots_force_sets import plot_force_sets

    af = load_airframe(args.airframe)
    poly = feasible_force_set(af)
    polygon = poly.slice_polygon(float(hover_force(af)[2]))
    print(f"airframe           {af.name}")
    print(f"S(0) facets        {len(poly.b)} (dimension {poly.dimension})")
    print(f"f_bz range         [{poly.z_range[0]:.3f}, {poly.z_range[1]:.3f}] N")
    if len(polygon):
        print(f"hover lateral max  |f_x| {np.abs(polygon[:, 0]).max():.3f} N, "
              f"|f_y| {np.abs(polygon[:, 1]).max():.3f} N (outer approximation)")
    print(f"approximation gap  {poly.gap:.3f} N ({100 * poly.relative_gap:.1f} %)")
    if args.plot is not None:
        plot_force_sets(af, args.plot)
        print(f"plot               {args.plot}")
    return 0


def _cmd_fmus(args: argparse.Namespace) -> int:
    for name in ("MultirotorPlant", "FullPoseController"):
        print(f"{name:20s} {fmu_path(name)}")
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="fullpose",
        description="Co-simulation of over-actuated multirotors (FMI 2.0 plant and controller).",
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")

    hover = sub.add_parser("hover", help="simulate the plant FMU hovering at trim (open loop)")
    hover.add_argument("--airframe", default="paper_hexacopter",
                       help="shipped airframe name or TOML file (default: paper_hexacopter)")
    hover.add_argument("--duration", type=float, default=10.0, help="seconds (default: 10)")
    hover.add_argument("--out", type=Path, default=None,
                       help="directory for hover.csv and hover_summary.json")
    hover.set_defaults(func=_cmd_hover)

    airframes = sub.add_parser("airframes", help="list the shipped airframe files")
    airframes.set_defaults(func=_cmd_airframes)

    fs = sub.add_parser("force-set", help="feasible force set S(0) of an airframe (paper Fig. 3)")
    fs.add_argument("--airframe", default="paper_hexacopter",
                    help="shipped airframe name or TOML file (default: paper_hexacopter)")
    fs.add_argument("--plot", type=Path, default=None, help="write the Fig.-3-like plot (PNG)")
    fs.set_defaults(func=_cmd_force_set)

    fmus = sub.add_parser("fmus", help="print where the installed FMUs are")
    fmus.set_defaults(func=_cmd_fmus)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.command is None:
        parser.print_help()
        return 0
    try:
        return int(args.func(args))
    except (AirframeError, NativeBuildMissing, ValueError) as e:
        print(f"fullpose: error: {e}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
