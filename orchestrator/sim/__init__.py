"""Running the FMUs: instances, the step engine, start values, the master of a scenario run,
live sessions, the hover demo, the lost-vehicle criteria."""
