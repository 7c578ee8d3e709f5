"""Message signing: incoming messages checked against the key in force, and SETUP_SIGNING
under the policy of docs/mavlink.md ("Signing policy"): a key changes only on the word of a
sender who proves a key (the one in force, or the one-time setup key)."""

from __future__ import annotations

from typing import Any

from mavlink_bridge.context import Context, Source
from mavlink_bridge.links import Endpoint, fresh_stamp, signature_error, signing_now
from mavlink_bridge.telemetry import mav


def refused(ctx: Context, msg: Any, src: Source) -> bool:
    """Whether msg is refused by signing (counted and told); sets ``ctx.signed``.  HEARTBEATs
    always pass, so an unsigned ground station still sees that the vehicle is there (but only
    a signed one makes its sender a udpin peer while signing is on)."""
    ctx.signed = False
    if not ctx.signing.enabled:
        return False
    kind = msg.get_type()
    hdr = msg.get_header()
    why = ctx.signing.verify(msg.get_msgbuf(), hdr.incompat_flags, src)
    ctx.signed = why is None
    if why is None or kind == "HEARTBEAT":
        return False
    ctx.signing.count(why)
    ctx.stats.refused_unsigned += 1
    ctx.statustext(mav.MAV_SEVERITY_WARNING, f"{kind[:26]} refused: {why}", limited=True)
    return True


def on_setup_signing(ctx: Context, ep: Endpoint, msg: Any, src: Source) -> None:
    """Policy (docs/mavlink.md, "Signing policy"): refused while armed and when the key was
    given with --signing-key; accepted only from an authenticated sender: signed with the
    key in force (a change of keys on a signed link), or, while no key is in force, signed
    with the one-time key of --signing-setup-key (spent by its first use).  Where the
    message came from (an endpoint, a port) proves nothing."""
    why = None
    if ctx.armed:
        why = "armed"
    elif ctx.config.signing_key is not None:
        why = "key set by --signing-key"
    elif ctx.signing.enabled:
        why = None if ctx.signed else "not signed with the key in force"
    elif ctx.setup_key is None:
        why = "no --signing-setup-key (or it was used)"
    else:
        hdr = msg.get_header()
        why = signature_error(ctx.setup_key, msg.get_msgbuf(), hdr.incompat_flags)
        if why is None and not fresh_stamp(msg.get_msgbuf(), signing_now()):
            why = "stale timestamp"
        if why is not None:
            why = f"{why} (not the --signing-setup-key)"
    if why is not None:
        ctx.statustext(mav.MAV_SEVERITY_WARNING, f"SETUP_SIGNING refused: {why}", limited=True)
        return
    key = bytes(int(b) & 0xFF for b in msg.secret_key)
    if len(key) != 32:
        return
    ctx.setup_key = None  # one-time: spent
    if not any(key) and int(msg.initial_timestamp) == 0:
        ctx.set_signing(None)
        ctx.statustext(mav.MAV_SEVERITY_NOTICE, "signing disabled")
        return
    ctx.set_signing(key, int(msg.initial_timestamp))
    ctx.statustext(mav.MAV_SEVERITY_NOTICE, "signing enabled with a new key")


HANDLERS = {"SETUP_SIGNING": on_setup_signing}
"""The signing messages."""
