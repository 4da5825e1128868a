"""Speed benchmarks: ``python bench/perf/run.py`` (``make bench``) and the long ones (``make bench-full``)."""
