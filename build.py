"""Build every FMU of the kit into build/fmu/ (or --out DIR) and validate each.

    python build.py [--out DIR] [script names]
"""
from fmu_src.python_build import main

if __name__ == "__main__":
    main(prog="python build.py")
