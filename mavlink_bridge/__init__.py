"""MAVLink bridge: fly the co-simulation from ground tools (MAVLink 2 on UDP, docs/mavlink.md)."""
