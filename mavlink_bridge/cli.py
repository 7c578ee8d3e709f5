"""``fullpose fly``: the bridge's command, joined to the ``fullpose`` CLI through the
``fullpose.commands`` entry point (``orchestrator.cli`` loads it; neither imports the other's
internals beyond its option helpers, and the orchestrator never imports the bridge)."""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path
from typing import Any

from mavlink_bridge.fleet import MAX_VEHICLES, SPACING
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
                          "default udpout:127.0.0.1:14550 and udpout:127.0.0.1:14540+i); "
                          "a port written PORT+i is PORT + the vehicle's instance number i "
                          "(0-based), any other URL is every vehicle's")
    fly.add_argument("-n", "--count", type=int, default=1, metavar="N",
                     help=f"fly N vehicles (1..{MAX_VEHICLES}), as PX4's "
                          "sitl_multiple_run.sh -n N: instance i has system id i+1, sends to "
                          "the shared ground-station port 14550 and to its own API port "
                          f"14540+i, and starts {SPACING:g}*i m east of the first "
                          "(default: 1)")
    fly.add_argument("--start", choices=("ground", "air"), default=None,
                     help="boot landed and disarmed on the landing gear (ground, as PX4 SITL) "
                          "or hovering (air); default: the scenario's, else ground for an "
                          "airframe with a landing gear, air without one")
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
    fly.add_argument("--pil", nargs="?", const="build", default=None, metavar="IMAGE",
                     help="fly the controller on an emulated Cortex-M7 (QEMU mps2-an500) in "
                          "place of its FMU; IMAGE: an fpc_pil.elf (default: built by "
                          "`fullpose build-embedded`); one vehicle")
    fly.set_defaults(func=_fly)


def _fly(args: argparse.Namespace) -> int:
    from mavlink_bridge.bridge import Bridge, BridgeConfig  # pymavlink: lazily
    from mavlink_bridge.fleet import DEFAULT_URLS, instance_urls
    from mavlink_bridge.links import load_key

    if not 1 <= args.count <= MAX_VEHICLES:
        raise ValueError(f"--count {args.count}: fly 1 to {MAX_VEHICLES} vehicles")
    if args.count > 1 and (args.view or args.save is not None):
        raise ValueError("--view and --save show one vehicle: not with --count above 1")
    speed = math.inf if args.speed.lower() == "max" else float(args.speed)
    if not speed > 0:
        raise ValueError("--speed must be positive or 'max'")
    if args.duration is not None and not args.duration > 0:
        raise ValueError("--duration must be positive")
    # the first vehicle's endpoints; with --count N the others' are derived from the same
    # templates (mavlink_bridge.fleet.fleet_configs)
    templates = list(args.gcs or DEFAULT_URLS)
    config = BridgeConfig(urls=instance_urls(templates, 0), speed=speed,
                          duration=args.duration, bridge_parameters=_limits(args.limit))
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
        config.start = sc.start
        if sc.mission is not None:  # held as the uploaded mission: arm and start it
            config.mission = sc.mission.items
            config.bridge_parameters = {**mission_parameters(sc.mission.settings),
                                        **(config.bridge_parameters or {})}
        if sc.origin is not None:
            from mavlink_bridge.geodesy import Origin

            config.origin = Origin(*sc.origin)
    else:
        from controller.design_check import lag_warning, read_gains
        from plant import load_airframe

        af = load_airframe(args.airframe or "paper_hexacopter")
        config.airframe = af
        if af.gear is None:
            config.start = "air"
            if args.start == "ground":
                raise ValueError(f"--start ground: airframe {af.name} has no landing gear "
                                 "([landing_gear] in its file, docs/airframes.md)")
        gains = read_gains(args.gains) if args.gains is not None else None
        if gains is not None:
            config.controller_parameters = gains.controller_parameters()
        lag_note = lag_warning(af, gains)
        if lag_note is not None:
            print(f"fullpose: warning: {lag_note}", file=sys.stderr)
    if args.start is not None:
        config.start = args.start
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
    if args.pil is not None:
        if args.count > 1:
            raise ValueError("--pil flies one vehicle: not with --count above 1")
        from orchestrator.pil.build import image_of

        config.pil = image_of(args.pil)
    if args.count > 1:
        return _fly_fleet(config, templates, args)
    if args.view:  # before the sockets open: a viewer that cannot show is said at once
        from orchestrator.output.view import check_viewer

        check_viewer()
    with Bridge(config) as bridge:
        af = bridge.airframe
        view = _live_view(bridge, args) if args.view or args.save is not None else None
        where = "resting on the ground, disarmed," if bridge.ground_start else "hovering"
        print(f"flying {af.name} {where} at "
              f"{tuple(round(float(x), 3) for x in bridge.session.pos0)} "
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


def _fly_fleet(config: Any, templates: list[str], args: argparse.Namespace) -> int:
    """``fly --count N``: N vehicles derived from the single vehicle's configuration
    (mavlink_bridge.fleet), each line of a vehicle prefixed by its system id."""
    from mavlink_bridge.fleet import Fleet, FleetError, fleet_configs

    configs = fleet_configs(config, args.count, templates)
    width = len(str(configs[-1].system_id))
    error: FleetError | None = None
    with Fleet(configs) as fleet:
        af = fleet.bridges[0].airframe
        pos = fleet.bridges[0].session.pos0
        where = "resting on the ground, disarmed," if config.start == "ground" else "hovering"
        print(f"flying {len(configs)} x {af.name} {where} at "
              f"{tuple(round(float(x), 3) for x in pos)} "
              f"in each one's local frame (speed {args.speed}, signing "
              f"{'on' if config.signing_key else 'off'})")
        for bridge in fleet.bridges:
            tag = f"[sys {bridge.config.system_id:>{width}}] "
            o = bridge.config.origin
            print(f"{tag}origin              {o.lat:.7f}, {o.lon:.7f}, {o.alt:.2f} m AMSL "
                  "(local NED 0)")
            for ep in bridge.endpoints:
                print(f"{tag}mavlink endpoint    {ep.url} (local {ep.sock.getsockname()[0]}:"
                      f"{ep.sock.getsockname()[1]})")
        sys.stdout.flush()
        try:
            fleet.run()
        except KeyboardInterrupt:
            pass  # Ctrl-C ends the flight, as for one vehicle: run() stopped them all
        except FleetError as e:
            error = e  # said after every vehicle's summary
        for bridge in fleet.bridges:
            tag = f"[sys {bridge.config.system_id:>{width}}] "
            for line in bridge.stats.lines():
                print(tag + line)
    if error is not None:
        raise error
    return 0


def mission_parameters(settings: Any) -> dict[str, float]:
    """A scenario mission's speeds and radii as the PX4 parameters the bridge flies with."""
    return {"MPC_XY_CRUISE": settings.cruise, "MPC_Z_VEL_MAX_UP": settings.climb,
            "MPC_Z_VEL_MAX_DN": settings.descent, "MPC_LAND_SPEED": settings.land,
            "MPC_ACC_HOR": settings.acc_hor, "NAV_ACC_RAD": settings.acceptance,
            "RTL_RETURN_ALT": settings.rtl_alt}


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


