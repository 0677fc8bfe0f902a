"""``fourierf-bench``: what accuracy costs in time.

A sweep (``sweep``) is expanded into independent runs; each run (``runner``) trains in its own ``fourierf-train``
process and is evaluated at checkpoints along its budget; runs go through an executor (``executors``: a local process
pool or a Ray cluster); every measurement lands in one CSV and ``report`` turns it into tables and plots.
"""
