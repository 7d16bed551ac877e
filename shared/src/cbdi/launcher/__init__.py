"""The launcher: `cbdi up SCENARIO` runs a scenario as supervised OS processes."""
