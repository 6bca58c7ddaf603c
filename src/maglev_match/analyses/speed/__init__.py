"""The vehicle at speed over identical spans: the sweep over speed (``sweep``, which also
re-exports the names of the modules it is built from: the settings ``options``, one span
``passage``, the ``critical`` disturbance at speed and everything at one speed ``point``),
runs over N spans (``spans``), maps with a speed axis (``maps``), the grid of speeds
(``grid``, light: the command line checks it before JAX loads) and Sperling's ride index
(``ride``)."""
