"""Instructions counted on the emulated Cortex-M7 as time on a flight controller.

QEMU counts instructions, not cycles.  The conversion assumes an STM32H7-class part at its
top clock and an average number of cycles per instruction (CPI):

* CLOCK_HZ = 480 MHz, the STM32H743/H753's maximum core clock;
* CPI = 1.0: the Cortex-M7 is a dual-issue, in-order core (up to two instructions a cycle;
  Arm quotes 2.14 DMIPS/MHz and 5.01 CoreMark/MHz for it against the Cortex-M4's 1.25 and
  3.42), while the controller's double-precision code spends cycles the count does not show
  (multi-cycle VDIV.F64 and VSQRT.F64, load-use and FPU result latencies), so one cycle per
  instruction is taken as the typical figure with code and data in tightly coupled or cached
  memory.  CPI_PESSIMISTIC = 2.0 bounds the cases that assumption misses (flash wait states
  without the cache, dependent chains of double-precision operations).

These are assumptions, not measurements: a board's own cycle counter (DWT CYCCNT) around
fpc_step measures the time there.
"""

from __future__ import annotations

CLOCK_HZ = 480e6
CPI = 1.0
CPI_PESSIMISTIC = 2.0
PERIOD_S = 0.002
"""The controller's sample time: the budget a sample's time is a share of."""


def microseconds(instructions: float, cpi: float = CPI, clock_hz: float = CLOCK_HZ) -> float:
    """Instructions as microseconds at clock_hz with cpi cycles each."""
    return instructions * cpi / clock_hz * 1e6


def period_share(instructions: float, cpi: float = CPI, period_s: float = PERIOD_S) -> float:
    """Instructions as a share of the sample period (0.0625 = 6.25 %)."""
    return microseconds(instructions, cpi) * 1e-6 / period_s
