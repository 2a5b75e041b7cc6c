"""Synthetic rigs, rendered frames and performances with exact truth, and scoring against
it: tools for the tests, the benchmarks and the demo. Not part of the product: the extension
zip leaves this package out, and no module of the core, the add-on or the command line
imports it (import-linter contract)."""
