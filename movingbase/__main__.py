"""Command line of the kit: ``movingbase COMMAND ...`` (or ``python -m movingbase``).

    movingbase                      the main job: the telescope slew and the paper's leg-force charts
    movingbase run SCENARIO ...     run scenario files or shipped names (movingbase run --help)
    movingbase campaign FILE        run a campaign of many scenario runs
    movingbase build                build every FMU (as build.py)
    movingbase headline             regenerate the README's headline from docs/headline.json
    movingbase --version
"""
import sys

from . import __version__

COMMANDS = ("run", "campaign", "build", "headline")


def main(argv=None):
    argv = sys.argv[1:] if argv is None else list(argv)
    if argv[:1] in (["--version"], ["-V"]):
        print(f"movingbase {__version__}")
        return
    if argv[:1] in (["-h"], ["--help"]):
        print(__doc__)
        return
    command, rest = (argv[0], argv[1:]) if argv and argv[0] in COMMANDS else ("run", argv)
    if command == "run":
        from .scenarios.__main__ import main as run
        return run(rest, prog="movingbase run")
    if command == "campaign":
        from .scenarios.campaign import main as campaign
        return campaign(rest)
    if command == "build":
        from .fmu_src.builder import main as build
        return build(rest)
    from .scenarios.headline import main as headline
    return headline(rest)


if __name__ == "__main__":
    main()
