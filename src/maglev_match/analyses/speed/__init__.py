"""The vehicle at speed over identical spans: the sweep over speed (``sweep``), runs over N
spans (``spans``), maps with a speed axis (``maps``), the grid of speeds (``grid``, light:
the command line checks it before JAX loads) and Sperling's ride index (``ride``)."""
