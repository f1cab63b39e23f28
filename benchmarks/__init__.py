"""sonarmap's benchmarks: ``python -m benchmarks`` (``make bench``) runs them all and prints
one table; each ``bench_*.py`` also runs on its own (see its docstring)."""
