"""``python -m ilcdob`` (and the ``ilcdob`` command) runs the command-line interface.

The interface is imported inside :func:`main`, so that a Ctrl-C while it loads (about a second)
ends with one line and exit 130, like a Ctrl-C later, and not with a traceback.
"""

import sys


def main() -> int:
    """Import the command-line interface and run it; returns the exit status."""
    try:
        from .app.cli import main as run
    except KeyboardInterrupt:
        sys.stderr.write("ilcdob: error: interrupted while starting; nothing was written\n")
        return 130
    return run()


if __name__ == "__main__":
    sys.exit(main())
