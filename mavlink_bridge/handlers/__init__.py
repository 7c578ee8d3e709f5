"""The bridge's message handlers, one module per protocol; :data:`HANDLERS` is the router's
table from message name to handler.  Every handler is ``(context, endpoint, message, sender)``
and answers through the :class:`~mavlink_bridge.context.Context`."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from mavlink_bridge.context import Context, Source
from mavlink_bridge.handlers import commands, missions, parameters, setpoints, signing, telemetry
from mavlink_bridge.links import Endpoint

Handler = Callable[[Context, Endpoint, Any, Source], None]
"""A message handler: (context, endpoint it came in on, message, sender)."""

HANDLERS: dict[str, Handler] = {
    **commands.HANDLERS,
    **setpoints.HANDLERS,
    **parameters.HANDLERS,
    **missions.HANDLERS,
    **signing.HANDLERS,
    **telemetry.HANDLERS,
}
"""Message name -> handler; a message not named here is counted as ignored."""
