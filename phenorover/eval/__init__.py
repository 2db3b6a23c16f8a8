"""The evaluation layer: benchmark results, truth scoring and paper comparisons.

It may import ``common`` and ``services``; nothing imports it but the tests, the
benchmarks and the CLI's dispatcher."""
