"""The identity the bridge shows ground stations: PX4, a firmware version QGroundControl
accepts, and the few PX4 parameters QGroundControl's PX4 plugin reads.

docs/mavlink.md ("Identity") gives the decision and the QGroundControl sources it rests
on.  The parameters are listed here in ``params.BRIDGE_PARAMETERS``' format (value, min,
max, description); min = max = value makes them read-only (a PARAM_SET to another
value is refused and answered with the value in force).
"""

from __future__ import annotations

FIRMWARE_VERSION_TYPE_DEV = 0  # common.xml FIRMWARE_VERSION_TYPE

#: AUTOPILOT_VERSION.flight_sw_version: major << 24 | minor << 16 | patch << 8 | type.
#: PX4 1.15.0, type DEV.  1.15 passes QGroundControl's PX4 check (PX4FirmwarePlugin::
#: _handleAutopilotVersion warns below 1.4.1 and for 0) and is the PX4 release whose
#: MAVLink behaviour the bridge follows.  DEV, not OFFICIAL: QGroundControl's
#: FirmwarePlugin::_versionFileDownloadFinished compares an OFFICIAL version with the
#: latest PX4 release on GitHub and tells the user to upgrade when it is older, which
#: any fixed number here becomes; this is not PX4 firmware, so it claims no release.
FLIGHT_SW_VERSION = (1 << 24) | (15 << 16) | (0 << 8) | FIRMWARE_VERSION_TYPE_DEV

#: PX4 parameters QGroundControl's PX4 plugin reads without first checking they exist
#: (a missing one raises "Parameters are missing from firmware"), or reads to decide
#: what to show.  Integers in PX4 (INT32); their values are exact as floats.
PX4_PARAMETERS: dict[str, tuple[float, float, float, str]] = {
    # AirframeComponent::setupComplete: non-zero = airframe chosen (4001: PX4's generic
    # quadcopter; the bridge's own airframe file defines the real geometry)
    "SYS_AUTOSTART": (4001.0, 4001.0, 4001.0, "PX4 airframe id (read-only)"),
    # PX4AutoPilotPlugin::prerequisiteSetup: stick input source; 4 = disabled (PX4 1.14+):
    # there are no sticks in this simulation
    "COM_RC_IN_MODE": (4.0, 4.0, 4.0, "PX4 stick input source: 4 = none (read-only)"),
    # PX4AutoPilotPlugin::parametersReadyPreChecks: 1 would show a HITL warning
    "SYS_HITL": (0.0, 0.0, 0.0, "PX4 hardware-in-the-loop flag (read-only)"),
}

INTEGER_PARAMETERS = frozenset(PX4_PARAMETERS)  # PX4 declares all of them INT32
