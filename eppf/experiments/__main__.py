"""``python -m eppf.experiments``: replaced by ``eppf experiment`` (also ``python -m eppf experiment``).

The experiments' command line is a subcommand of ``eppf`` (:mod:`eppf.cli`);
this module only says so, since the experiments sit below the command line.
"""

import shlex
import sys

if __name__ == "__main__":
    print("python -m eppf.experiments: error: the experiments' command line is now 'eppf experiment' (or "
          f"'python -m eppf experiment'): eppf experiment {shlex.join(sys.argv[1:])}".rstrip(), file=sys.stderr)
    sys.exit(2)
