"""Time integration: simulate, the flow and its derivatives, exact stick-slip."""
