"""Sub-commands of the ``ebraille-sim`` command line.

Each module in this package defines ``NAME`` (the sub-command), ``HELP`` (one line),
``add_arguments(parser)`` and ``main(args) -> int``; :mod:`ebraille_sim.cli` finds them
with :mod:`pkgutil`, so a new sub-command is a new module here.  Errors meant for the
user are raised as :class:`UserError` (or ``ValueError``/``FileNotFoundError``) and
printed as one ``error: ...`` line with exit status 2.
"""


class UserError(Exception):
    """An input problem to report as one line (exit status 2)."""
