"""``fullpose fly``: the bridge's command, joined to the ``fullpose`` CLI through the
``fullpose.commands`` entry point (``orchestrator.cli`` loads it; neither imports the other's
internals beyond its option helpers, and the orchestrator never imports the bridge)."""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path
from typing import Any

from orchestrator.cli import add_vehicle_options


def register(sub: Any) -> None:
    """Adds ``fly`` to the ``fullpose`` subparsers."""
    fly = sub.add_parser("fly", help="fly the vehicle in real time from MAVLink ground tools")
    fly.add_argument("scenario", nargs="?", default=None,
                     help="start from this scenario's airframe, pose and parameters")
    add_vehicle_options(fly, "shipped airframe name or TOML file (default: the scenario's, "
                             "else paper_hexacopter)")
    fly.add_argument("--gcs", action="append", default=[], metavar="URL",
                     help="MAVLink endpoint, udpout:HOST:PORT or udpin:HOST:PORT (repeatable; "
                          "default udpout:127.0.0.1:14550 and udpout:127.0.0.1:14540)")
    fly.add_argument("--speed", default="1", metavar="X",
                     help="simulated seconds per wall second, or 'max' (default: 1)")
    fly.add_argument("--signing-key", default=None, metavar="FILE",
                     help="MAVLink 2 signing key: 32 bytes, 64 hex digits or a passphrase")
    fly.add_argument("--origin", default=None, metavar="LAT,LON,ALT",
                     help="WGS84 point of the local NED origin (deg, deg, m AMSL; default: "
                          "PX4 SITL's home 47.397742,8.545594,488; a negative LAT: "
                          "--origin=-33.9,151.2,40)")
    fly.add_argument("--signing-setup-key", default=None, metavar="FILE",
                     help="a one-time key (as --signing-key): the first SETUP_SIGNING signed "
                          "with it, while disarmed, installs the key it carries (default: "
                          "SETUP_SIGNING only on a link already signed)")
    fly.add_argument("--limit", action="append", default=[], metavar="FPB_NAME=VALUE",
                     help="set a safety limit or timeout of the bridge (e.g. "
                          "FPB_SP_XY_MAX=200; repeatable); over MAVLink they change only on a "
                          "signed link")
    fly.add_argument("--duration", type=float, default=None, metavar="S",
                     help="stop after S simulated seconds (default: run until Ctrl-C)")
    fly.add_argument("--view", action="store_true",
                     help="watch the flight in 3-D (Rerun): pip install 'fullpose[view]'")
    fly.add_argument("--save", type=Path, default=None, metavar="FILE.rrd",
                     help="write the 3-D view of the flight as a Rerun recording")
    fly.set_defaults(func=_fly)


def _fly(args: argparse.Namespace) -> int:
    from mavlink_bridge.bridge import DEFAULT_URLS, Bridge, BridgeConfig  # pymavlink: lazily
    from mavlink_bridge.links import load_key

    speed = math.inf if args.speed.lower() == "max" else float(args.speed)
    if not speed > 0:
        raise ValueError("--speed must be positive or 'max'")
    if args.duration is not None and not args.duration > 0:
        raise ValueError("--duration must be positive")
    urls = list(args.gcs or DEFAULT_URLS)
    config = BridgeConfig(urls=urls, speed=speed, duration=args.duration,
                          bridge_parameters=_limits(args.limit))
    if args.scenario is not None:
        from orchestrator.runner import prepare

        sc = prepare(args.scenario, airframe=args.airframe, gains=args.gains)
        pos0, euler0 = sc.initial_pose()
        config.airframe, config.pos0, config.euler0 = sc.airframe, tuple(pos0), tuple(euler0)
        for warning in sc.warnings:
            print(f"fullpose: warning: {warning}", file=sys.stderr)
        config.plant_parameters = sc.plant_parameters
        config.controller_parameters = sc.controller_parameters
        config.coupling = sc.coupling
        if sc.origin is not None:
            from mavlink_bridge.geodesy import Origin

            config.origin = Origin(*sc.origin)
    else:
        from controller.design_check import lag_warning, read_gains
        from plant import load_airframe

        af = load_airframe(args.airframe or "paper_hexacopter")
        config.airframe = af
        gains = read_gains(args.gains) if args.gains is not None else None
        if gains is not None:
            config.controller_parameters = gains.controller_parameters()
        lag_note = lag_warning(af, gains)
        if lag_note is not None:
            print(f"fullpose: warning: {lag_note}", file=sys.stderr)
    if args.origin is not None:
        from mavlink_bridge.geodesy import parse_origin

        config.origin = parse_origin(args.origin)
    for option, path in (("signing_key", args.signing_key),
                         ("signing_setup_key", args.signing_setup_key)):
        if path is not None:
            try:
                setattr(config, option, load_key(path))
            except (OSError, UnicodeDecodeError) as e:
                raise ValueError(f"--{option.replace('_', '-')}: {e}") from None
    if args.view:  # before the sockets open: a viewer that cannot show is said at once
        from orchestrator.output.view import check_viewer

        check_viewer()
    with Bridge(config) as bridge:
        af = bridge.airframe
        view = _live_view(bridge, args) if args.view or args.save is not None else None
        print(f"flying {af.name} from {tuple(float(x) for x in config.pos0)} "
              f"(speed {args.speed}, signing {'on' if config.signing_key else 'off'})")
        o = config.origin
        print(f"origin              {o.lat:.7f}, {o.lon:.7f}, {o.alt:.2f} m AMSL (local NED 0)")
        for ep in bridge.endpoints:
            print(f"mavlink endpoint    {ep.url} (local {ep.sock.getsockname()[0]}:"
                  f"{ep.sock.getsockname()[1]})")
        sys.stdout.flush()
        try:
            stats = bridge.run()
        except KeyboardInterrupt:
            stats = bridge.stats
        finally:
            if view is not None:
                view.close()
        for line in stats.lines():
            print(line)
        if view is not None:
            share = view.seconds / stats.wall_time if stats.wall_time > 0 else 0.0
            print(f"3-D view            {view.logged} moments logged in {view.seconds:.2f} s "
                  f"({100 * share:.1f} % of the wall time)"
                  + (f", wrote {args.save}" if args.save is not None else ""))
    return 0


def _limits(settings: list[str]) -> dict[str, float]:
    """The --limit NAME=VALUE settings (checked against the parameter table by the bridge)."""
    out = {}
    for setting in settings:
        name, sep, text = setting.partition("=")
        try:
            value = float(text)
        except ValueError:
            value = math.nan
        if not sep or not name.strip() or not math.isfinite(value):
            raise ValueError(f"--limit {setting!r}: expected FPB_NAME=NUMBER")
        out[name.strip()] = value
    return out


def _live_view(bridge: Any, args: argparse.Namespace) -> Any:
    """A 3-D view fed after each chunk the bridge flies."""
    from orchestrator.output.view import LiveView

    view = LiveView(bridge.airframe, args.save, spawn=args.view, start=bridge.config.pos0)

    def on_chunk(b: Any) -> None:
        t = b.session.time
        view.log(t, b.state, b.ref.pos, b.ref.euler,
                 {"mode": b.mode, "armed": b.armed,
                  "setpoints": "streaming" if t - b.last_setpoint <= b.stale else "stale"})

    bridge.on_chunk = on_chunk
    return view


