"""MAVLink bridge: fly the co-simulation from ground tools (issue: MAVLink bridge)."""
