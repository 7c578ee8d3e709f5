"""Helpers every package uses (the Python counterpart of ``fmu_src/common/``): finding and
loading built artifacts, reading a modelDescription, the validating TOML reader."""
