"""The names of a run's figures, in a module of their own so that naming them imports no
matplotlib (the run's parent process hands names to the figure workers) and the figures'
module and the workers' pool need not import each other."""

RUN_FIGURES = ("tracking", "actuators", "forces", "disturbance_timing")
"""The figures of every run (``orchestrator.output.plots``), in the order
:func:`~orchestrator.output.plots.plot_run` writes them (then ``force_set``)."""
