"""The controller on a flight-controller processor: its cross build (``build``), the image
run under QEMU (``target``), that image in a closed loop in place of the controller FMU
(``instance``: processor in the loop) and what its instruction counts cost on a board
(``cost``).  docs/embedded.md."""
