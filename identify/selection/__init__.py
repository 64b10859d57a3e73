"""Choosing one model from the path: the Pareto step and refit, the free-run term budget."""
