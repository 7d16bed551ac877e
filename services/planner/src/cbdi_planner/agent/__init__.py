"""The planner on the bus: an agent's beliefs to problems, plans to executable steps, and
the planner service (offline mode: plan, then act; continual mode is issue 4)."""
