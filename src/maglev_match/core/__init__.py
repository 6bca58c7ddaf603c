"""The ground floor: parameter sets, units, files, errors, options, checkpoints and
the JAX set-up. Nothing here knows a maglev model or a numerical method."""
