"""Free run of a model: simulation, validation, output-error refine, multiple shooting."""
