"""Command line of the kit: ``movingbase COMMAND ...`` (or ``python -m movingbase``).

    movingbase                      the main job: the telescope slew and the paper's leg-force charts
    movingbase run SCENARIO ...     run scenario files or shipped names (movingbase run --help)
    movingbase campaign FILE        run a campaign of many scenario runs
    movingbase build                build every FMU (as build.py)
    movingbase headline             regenerate the README's headline from docs/headline.json
    movingbase --version
"""
import atexit
import os
import signal
import sys

from movingbase import __version__

COMMANDS = ("run", "campaign", "build", "headline")


def main(argv=None):
    """The command. As the program (``argv`` None: the console command or ``python -m
    movingbase``) the process ends right after its exit handlers, without the
    interpreter's teardown: freeing numpy's, matplotlib's, fmpy's and the FMUs' modules one
    by one took 0.2-0.3 s of a 2.6 s run (docs/speed.md); every file is closed by then."""
    if argv is not None:
        return _command(list(argv))
    signal.signal(signal.SIGTERM, _terminated)
    for stream in (sys.stdout, sys.stderr):   # a file name or message the locale cannot encode (ASCII,
        stream.reconfigure(errors="backslashreplace")   # Latin-1): shown escaped, never a UnicodeEncodeError
    try:
        status = _command(sys.argv[1:])
    except SystemExit as exc:
        status = exc.code
    if status is not None and not isinstance(status, int):   # sys.exit("message"): printed, status 1
        print(status, file=sys.stderr)
        status = 1
    exit_now(status or 0)


def _terminated(signum, frame):
    """SIGTERM (kill, a batch system's time limit) ends the command as Ctrl-C does: through
    its cleanup (the workers stopped, the unpacked FMUs removed), status 143."""
    raise SystemExit(128 + signum)


def exit_now(status):
    """End the process with ``status`` after its exit handlers (temporary folders) and with
    stdout and stderr flushed, without the interpreter's teardown (the command's and the
    test session's end: see main and tests/conftest.py)."""
    atexit._run_exitfuncs()
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(status)


def _command(argv):
    if argv[:1] in (["--version"], ["-V"]):
        print(f"movingbase {__version__}")
        return
    if argv[:1] in (["-h"], ["--help"]):
        print(__doc__)
        return
    command, rest = (argv[0], argv[1:]) if argv and argv[0] in COMMANDS else ("run", argv)
    if command == "run":
        from movingbase.run_command import main as run
        return run(rest, prog="movingbase run")
    if command == "campaign":
        from scenarios.runs.campaign import main as campaign
        return campaign(rest)
    if command == "build":
        from fmu_src.python_build import main as build
        try:
            build(rest)    # it returns the output folder: not an exit status
        except OSError as exc:      # --out onto a file, a folder it may not write, a full disk
            return f"build error: {_os_problem(exc)}"
        return None
    from scenarios.output.headline import main as headline
    try:
        return headline(rest)
    except OSError as exc:          # --from a folder without the full runs' results
        return f"headline error: {_os_problem(exc)} (--from names the --out of the full runs: movingbase run)"
    except (ValueError, KeyError) as exc:     # a metrics.json that is not the kit's
        return f"headline error: --from {rest[-1] if rest else ''}: results that are not the full runs' ({exc!r:.200})"


def _os_problem(exc):
    """'<path>: <what>' of an OSError, a file where a folder belongs said so."""
    target = exc.filename or ""
    return f"{target}: {'is a file, not a folder' if os.path.isfile(target) else exc.strerror or exc}"


if __name__ == "__main__":
    main()
