"""Helpers of the test suites and benchmarks: evaluation recordings, drawings, plans, the CLI."""
