"""Tests of the benchmark tools (tools/)."""
