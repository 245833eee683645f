"""The commands of the ``snapmem`` CLI, in modules by what they share: option parsing and output
checks (common.py), branch commands (branches.py: trace, fold, hysteresis). ``snapmem.cli`` builds
the parser and runs them."""
