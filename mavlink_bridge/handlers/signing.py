"""Message signing: incoming messages checked against the key in force, and SETUP_SIGNING
under the policy of docs/mavlink.md ("Signing policy")."""

from __future__ import annotations

from typing import Any

from mavlink_bridge.context import Context, Source
from mavlink_bridge.links import Endpoint
from mavlink_bridge.telemetry import mav


def refused(ctx: Context, msg: Any, src: Source) -> bool:
    """Whether msg is refused by signing (counted and told); HEARTBEATs always pass, so an
    unsigned ground station still sees that the vehicle is there."""
    kind = msg.get_type()
    if not ctx.signing.enabled or kind == "HEARTBEAT":
        return False
    hdr = msg.get_header()
    why = ctx.signing.verify(msg.get_msgbuf(), hdr.incompat_flags, src)
    if why is None:
        return False
    ctx.signing.count(why)
    ctx.stats.refused_unsigned += 1
    ctx.statustext(mav.MAV_SEVERITY_WARNING, f"{kind[:26]} refused: {why}", limited=True)
    return True


def on_setup_signing(ctx: Context, ep: Endpoint, msg: Any, src: Source) -> None:
    """Policy (docs/mavlink.md, "Signing policy"): refused while armed, refused when the
    key was given with --signing-key, accepted only from a --signing-setup-from link."""
    why = None
    if ctx.armed:
        why = "armed"
    elif ctx.config.signing_key is not None:
        why = "key set by --signing-key"
    elif ep.url not in ctx.config.signing_setup_from:
        why = "not --signing-setup-from"
    if why is not None:
        ctx.statustext(mav.MAV_SEVERITY_WARNING, f"SETUP_SIGNING refused: {why}", limited=True)
        return
    key = bytes(int(b) & 0xFF for b in msg.secret_key)
    if len(key) != 32:
        return
    if not any(key) and int(msg.initial_timestamp) == 0:
        ctx.set_signing(None)
        ctx.statustext(mav.MAV_SEVERITY_NOTICE, "signing disabled")
        return
    ctx.set_signing(key, int(msg.initial_timestamp))
    ctx.statustext(mav.MAV_SEVERITY_NOTICE, "signing enabled with a new key")


HANDLERS = {"SETUP_SIGNING": on_setup_signing}
"""The signing messages."""
