"""The one exception hierarchy of panel_deploy.

Exceptions are for misuse (bad input, wrong call); a simulation or optimisation
that runs but fails returns a result with ``success=False`` instead.
"""


class PanelDeployError(Exception):
    """Base class of every error panel_deploy raises on purpose."""


class SceneError(PanelDeployError, ValueError):
    """A scene file or scene dictionary is invalid.

    The message starts with the key path of the offending field, e.g.
    ``simulation.rtol: expected a number > 0, got -1``.
    """

    def __init__(self, path, message):
        self.path = path
        self.reason = message
        super().__init__(f"{path}: {message}" if path else message)


class DesignError(PanelDeployError, ValueError):
    """A fold design request cannot be met (no circuit, not packable, bad cells)."""


class ModelError(PanelDeployError, ValueError):
    """A model cannot be built or used as asked (bad body, hinge or index)."""


class TrajectoryError(PanelDeployError, ValueError):
    """A saved trajectory or recording is missing, corrupt or of the wrong shape."""


class OptimisationError(PanelDeployError, ValueError):
    """An optimisation request is invalid (bounds, groups, start point, cluster)."""


#: Longest shown value in a message: a value read from a file or a message can
#: be any size (YAML aliases expand a small file a million fold), and one line
#: must stay one readable line.
SHOWN_LENGTH = 80


def _short_repr():
    import reprlib

    class Short(reprlib.Repr):
        def repr_int(self, x, level):
            # repr of an integer of more than 4300 digits raises ValueError
            if x.bit_length() < 4 * SHOWN_LENGTH:
                return repr(x)
            return f"<an integer of about {int(x.bit_length() * 0.30103) + 1} digits>"

    r = Short()
    r.maxlevel, r.maxstring, r.maxother = 3, SHOWN_LENGTH, SHOWN_LENGTH
    return r


_REPR = _short_repr()


def shown(value) -> str:
    """``repr(value)`` for an error message, at most :data:`SHOWN_LENGTH` characters
    (longer ones end in ``...``); only the part shown is ever formatted."""
    text = _REPR.repr(value)
    return text if len(text) <= SHOWN_LENGTH else text[:SHOWN_LENGTH - 3] + "..."
