"""gcpfree's benchmarks: speed (``bench/perf``), accuracy studies (``bench/validation``), the peers they measure against (``bench/peers``) and what they share (``bench.common``)."""
