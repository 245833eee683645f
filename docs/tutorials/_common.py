"""What every tutorial script shares: ``--quick`` (small settings, what the tests run) and ``--out``."""

import argparse
from pathlib import Path


def parse(doc: str, argv=None, **extra):
    """Parse ``--quick`` and ``--out DIR`` (default: a folder ``out/`` beside the script)."""
    parser = argparse.ArgumentParser(description=doc.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="small settings (seconds)")
    parser.add_argument("--out", type=Path, default=Path(__file__).parent / "out", help="output folder")
    for name, options in extra.items():
        parser.add_argument(f"--{name.replace('_', '-')}", **options)
    args = parser.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    return args
