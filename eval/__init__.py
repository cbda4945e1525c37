"""torchsar evaluation harness: datasets, detector registry, runner, tables, plots, CLI."""
