"""Build every FMU of the kit into build/fmu/ (or --out DIR) and validate each: the
pythonfmu FMUs (FMI 2.0), their native twins (FMI 2.0) and the native FMI 3.0 FMUs.

    python build.py [--out DIR] [script names]
"""
from movingbase.cli import build_command

if __name__ == "__main__":
    build_command(prog="python build.py")
