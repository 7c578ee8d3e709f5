"""FMUs for other platforms and tools: the multi-platform build (Zig), the Mach-O check,
the SSP export of the closed loop."""
