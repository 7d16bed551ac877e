"""cbdi monitor: record all cbdi traffic to MCAP, replay it, inspect it, view it in rerun."""
