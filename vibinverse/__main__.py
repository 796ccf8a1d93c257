import sys

try:
    from vibinverse.cli import entry
except KeyboardInterrupt:  # Ctrl-C while the interpreter starts: one line, no traceback
    print("vibinverse: interrupted", file=sys.stderr)
    sys.exit(130)

entry()
