"""The source papers' experiments as ``torchsar-eval`` sub-commands, kept apart from the
evaluator: ``pfa`` (measured false-alarm rates against the design), ``speckle`` (filters
scored on simulated and real chips), ``autofocus`` (sparse imaging with phase-error
correction on simulated and GOTCHA data), ``movers`` (the subpatch moving-target detector's
ladder) and ``compare-region`` (the region-growing CFAR against the window CFARs).

Each module has ``add_parser(subparsers)`` and ``run(args) -> int`` like the evaluator's own
commands; they use the evaluator (datasets, output folders, tables, plots), and nothing in the
evaluator imports them (``tests/test_imports.py``). As there, their heavy imports are inside
their functions: ``torchsar-eval --help`` imports every command's module for its parser.
"""
