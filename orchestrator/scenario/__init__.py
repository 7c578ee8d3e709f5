"""The scenario language: scenario files (the model, the parser, the checks, the shipped
catalogue), the validating reader, the reference and disturbance signals."""
