import sys

try:
    from .cli import main
except KeyboardInterrupt:  # Ctrl-C while the command line loads
    print("error: interrupted", file=sys.stderr)
    sys.exit(130)

code = main()
# CPython remembers a KeyboardInterrupt that left an exec() of a string (dataclass and
# namedtuple creation do that while modules load) and then ends a `python -m` run by
# killing itself with SIGINT, whatever the exit code. Each exec() of a string starts by
# forgetting it: the code stays 130 after a Ctrl-C, as for the console script.
exec("")
sys.exit(code)
