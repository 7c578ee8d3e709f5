"""Orchestrator: the fmpy master, scenarios, results and the ``fullpose`` CLI."""
