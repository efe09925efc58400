"""Shared input and output checks (ROS-free): the CLI and the nodes use the same rules.

* :func:`load_yaml`: YAML read by :class:`StrictLoader`, which refuses a key
  given twice in one mapping, nesting deeper than :data:`MAX_YAML_DEPTH` and
  aliases that expand the document beyond :data:`MAX_YAML_EXPANDED`.
* :func:`check_output_path`: an output path is checked before any work is
  done (its folder exists and is writable, the path is not a folder).
* :func:`write_atomic`: write through a temporary file renamed into place
  (:func:`temporary_beside`; a device or pipe, :func:`in_place`, is written
  as it is); if the write fails after all (a full disk, ``/dev/full``, a file
  size limit), the content goes to a fallback file in the working directory
  (or the temporary folder) and the error says where; a fallback that fails
  too is removed.
* :func:`read_text`: a text file read with every failure a one-line error.
* :func:`check_finite`: an array with NaN or inf refused naming the array and
  the first bad index.

Every error is a :class:`~panel_deploy.errors.PanelDeployError` whose message
names the field (a flag as the user typed it, a key path, a file and array).
"""

from __future__ import annotations

import errno
import math
import os
import tempfile
from pathlib import Path

import numpy as np
import yaml

from .errors import PanelDeployError, SceneError, shown

#: Deepest nesting of YAML collections accepted: a scene is four levels deep
#: (section, key, list, pair); anything far deeper is a mistake or an attack
#: (and would exhaust Python's recursion limit).
MAX_YAML_DEPTH = 32
#: Largest size (nodes plus scalar characters: about the length of the text)
#: a document's aliases may expand it to. A scene or result file is a few kB;
#: without this bound nine lines of anchors and aliases (billion laughs) expand
#: to 10^9 values, and anything that walks or prints them takes gigabytes.
MAX_YAML_EXPANDED = 1_000_000


class StrictLoader(yaml.SafeLoader):
    """``yaml.SafeLoader`` refusing duplicate keys, nesting beyond :data:`MAX_YAML_DEPTH`
    and aliases expanding the document beyond :data:`MAX_YAML_EXPANDED`.

    A repeated key (``simulation:`` twice) would otherwise keep the last
    value silently and drop the first. Aliases (and merge keys) stay allowed
    within the bound: the depth and size of a document that has any are
    measured on what they expand to, since that is what consumers walk.
    """

    max_depth = MAX_YAML_DEPTH
    max_expanded = MAX_YAML_EXPANDED

    def compose_document(self):
        self._aliased = False
        node = super().compose_document()
        if self._aliased:
            self._expanded(node, 0, {})
        return node

    def _expanded(self, node, depth, memo) -> tuple:
        """``(size, height)`` of ``node`` with its aliases written out; raises past the bounds.

        Memoised per node, so a bomb costs its number of distinct nodes; a
        recursive alias never ends and so fails the depth bound.
        """
        known = memo.get(id(node))
        if known is None:
            if depth >= self.max_depth:
                raise yaml.composer.ComposerError(
                    None, None, f"aliases nest it deeper than {self.max_depth} levels (the limit "
                                "of a scene file)", node.start_mark)
            if isinstance(node, yaml.ScalarNode):
                known = (1 + len(node.value), 0)
            else:
                children = (node.value if isinstance(node, yaml.SequenceNode)
                            else [n for pair in node.value for n in pair])
                size, height = 1, 0
                for child in children:
                    s, h = self._expanded(child, depth + 1, memo)
                    size, height = size + s, max(height, h + 1)
                    if size > self.max_expanded:
                        raise yaml.composer.ComposerError(
                            None, None, f"aliases expand it beyond {self.max_expanded} values "
                                        "and characters (the limit of a scene file)",
                            node.start_mark)
                known = (size, height)
            memo[id(node)] = known
        if depth + known[1] >= self.max_depth:
            raise yaml.composer.ComposerError(
                None, None, f"aliases nest it deeper than {self.max_depth} levels (the limit "
                            "of a scene file)", node.start_mark)
        return known

    def compose_node(self, parent, index):
        if self.check_event(yaml.AliasEvent):
            self._aliased = True
        depth = getattr(self, "_depth", 0)
        if depth >= self.max_depth:
            mark = self.peek_event().start_mark
            raise yaml.composer.ComposerError(
                None, None, f"nested deeper than {self.max_depth} levels (the limit of a scene "
                            "file)", mark)
        self._depth = depth + 1
        try:
            return super().compose_node(parent, index)
        finally:
            self._depth = depth

    def construct_object(self, node, deep=False):
        try:
            return super().construct_object(node, deep=deep)
        except ValueError as e:  # a scalar of the right form but no value: 2001-02-30, 10^5000
            reason = str(e).split(";")[0].split(": value has")[0]
            raise yaml.constructor.ConstructorError(
                None, None, f"cannot read {shown(node.value)} ({reason})", node.start_mark) from None

    def construct_mapping(self, node, deep=False):
        if isinstance(node, yaml.MappingNode):
            seen = {}
            for key_node, _ in node.value:
                if key_node.tag == "tag:yaml.org,2002:merge":
                    continue
                try:
                    key = self.construct_object(key_node, deep=True)
                    hash(key)
                except (TypeError, yaml.YAMLError):
                    continue  # the base class reports an unhashable key
                if key in seen:
                    raise yaml.constructor.ConstructorError(
                        None, None, f"duplicate key {shown(key)} (first given at line "
                                    f"{seen[key].line + 1})", key_node.start_mark)
                seen[key] = key_node.start_mark
        return super().construct_mapping(node, deep=deep)


def load_yaml(text):
    """``yaml.load(text, StrictLoader)``: raises ``yaml.YAMLError`` as safe_load does."""
    try:
        return yaml.load(text, Loader=StrictLoader)  # noqa: S506 (a SafeLoader subclass)
    except RecursionError:
        raise yaml.YAMLError(f"nested too deeply (more than {MAX_YAML_DEPTH} levels)") from None


def yaml_problem(e: yaml.YAMLError) -> str:
    """One line on a YAML error: ``at line L, column C: problem``."""
    mark = getattr(e, "problem_mark", None)
    where = f"at line {mark.line + 1}, column {mark.column + 1}: " if mark else ""
    problem = getattr(e, "problem", None) or (str(e).splitlines() or ["invalid"])[0]
    return where + problem


def read_text(path, what: str = "file") -> str:
    """The text of ``path`` (UTF-8), every failure a :class:`PanelDeployError` naming it."""
    path = Path(path)
    try:
        return path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise PanelDeployError(f"{path}: {what} not found") from None
    except IsADirectoryError:
        raise PanelDeployError(f"{path}: {what} is a folder, not a file") from None
    except UnicodeDecodeError as e:
        raise PanelDeployError(f"{path}: {what} is not UTF-8 text (byte {e.start})") from None
    except (OSError, ValueError) as e:
        raise PanelDeployError(f"{path}: cannot read {what} ({getattr(e, 'strerror', None) or e})") from None


def check_output_path(path, flag: str) -> Path | None:
    """Check that ``path`` can be written, before any work is done.

    Its folder must exist and take the temporary file of :func:`write_atomic`
    and the path must not be a folder (an existing file is replaced). Raises :class:`SceneError` naming ``flag``
    (``--out``). None passes (no output asked for).
    """
    if path is None:
        return None
    text = str(path)
    if not text.strip():
        raise SceneError(flag, "expected a file name, got an empty string")
    p = Path(text)
    if "\0" in text:
        raise SceneError(flag, f"{shown(text)} is not a valid path")
    try:
        _check_writable(p, text, flag)
    except OSError as e:  # a name too long, a path through a file, ...
        raise SceneError(flag, f"cannot write {text}: {e.strerror or e}") from None
    return p


def _check_writable(p: Path, text: str, flag: str) -> None:
    if is_stdout(text):
        return  # written in place, where the shell or pipe reads
    p = output_target(p)
    if p.is_dir() or text.endswith(("/", os.sep)):
        raise SceneError(flag, f"{text} is a folder; give a file name")
    parent = p.parent
    if not parent.exists():
        raise SceneError(flag, f"cannot write {text}: folder {parent} does not exist")
    if not parent.is_dir():
        raise SceneError(flag, f"cannot write {text}: {parent} is not a folder")
    if not os.access(parent, os.W_OK | os.X_OK):
        raise SceneError(flag, f"cannot write {text}: folder {parent} is not writable")
    if p.exists() and not os.access(p, os.W_OK):
        raise SceneError(flag, f"{text} exists and is not writable")
    if not p.exists() or p.is_file():
        # the temporary file write_atomic will write: the folder may refuse new
        # files (/proc) or the name with its temporary affixes be too long
        try:
            fd, probe = temporary_beside(p, f".{p.name}.", ".part")
        except OSError as e:
            if e.errno == errno.ENAMETOOLONG:
                raise
            raise SceneError(flag, f"cannot write {text}: folder {parent} does not take new "
                                   f"files ({e.strerror or e})") from None
        os.close(fd)
        os.unlink(probe)


def fallback_path(path) -> Path:
    """Where content meant for ``path`` goes when ``path`` cannot be written:
    ``panel-deploy-rescued-<name>`` in the working directory, else in the
    temporary folder (a new name, never overwriting)."""
    name = Path(path).name or "output"
    for folder in (Path.cwd(), Path(tempfile.gettempdir())):
        if os.access(folder, os.W_OK | os.X_OK):
            stem, suffix = Path(name).stem, "".join(Path(name).suffixes)
            fd, tmp = tempfile.mkstemp(dir=folder, prefix=f"panel-deploy-rescued-{stem}-",
                                       suffix=suffix)
            os.close(fd)
            return Path(tmp)
    raise OSError("neither the working directory nor the temporary folder is writable")


def _umask() -> int:
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def foreign_file(path) -> str | None:
    """What an input that is none of our files is, and what to do with it
    (a rosbag2 folder or SQLite bag: convert it to MCAP), or None."""
    path = Path(path)
    try:
        if path.is_dir():
            if (path / "metadata.yaml").is_file():
                return ("a rosbag2 folder: convert it to one MCAP file (ros2 bag convert, "
                        "storage mcap) and give the .mcap file")
            return "is a folder, not a file"
        with open(path, "rb") as f:
            head = f.read(16)
    except OSError:
        return None
    if head.startswith(b"SQLite format 3"):
        return ("an SQLite file (a rosbag2 .db3 bag?): convert the bag to MCAP (ros2 bag "
                "convert, storage mcap) and give the .mcap file")
    return None


#: Longest file name (bytes) of the file systems we write to.
NAME_MAX = 255

#: The output name that means standard output.
STDOUT = "-"


def is_stdout(path) -> bool:
    """Whether writing ``path`` writes this process's standard output: ``-``,
    ``/dev/stdout``, or any name (a link to ``/proc/self/fd/1``, the file the
    shell redirected to) of the file or pipe that standard output is."""
    if str(path) == STDOUT:
        return True
    try:
        here, out = os.stat(path), os.fstat(1)
    except (OSError, ValueError):
        return False
    return (here.st_dev, here.st_ino) == (out.st_dev, out.st_ino)


def in_place(path) -> bool:
    """Whether ``path`` is written in place: a device or a pipe (``/dev/null``,
    ``/dev/full``, a FIFO), where renaming a file over it would replace the
    device itself, or standard output (:func:`is_stdout`), which a shell or a
    pipe reads from the descriptor it holds."""
    path = Path(path)
    return is_stdout(path) or (path.exists() and not path.is_file())


def output_target(path) -> Path:
    """Where an output named ``path`` goes: the file a link points to (a link is
    written through, never replaced by a file), ``/dev/stdout`` for ``-``."""
    if str(path) == STDOUT:
        return Path("/dev/stdout")
    path = Path(path)
    # A link to a device, a pipe or standard output is written in place, through it.
    return Path(os.path.realpath(path)) if path.is_symlink() and not in_place(path) else path


def temporary_beside(path, prefix: str, suffix: str) -> tuple[int, str]:
    """``(fd, name)`` of a new file in ``path``'s folder (``prefix`` + random +
    ``suffix``), with the mode ``open()`` would give it (mkstemp's is 0600):
    written there and renamed over ``path`` at the end, it replaces ``path``
    at once, or not at all."""
    folder = Path(path).parent if str(Path(path).parent) else Path(".")
    # A name the file system takes (255 bytes) must not fail for its affixes:
    # the prefix gives way (mkstemp adds 8 characters).
    room = NAME_MAX - 8 - len(suffix.encode())
    while len(prefix.encode()) > room:
        prefix = prefix[:-1]
    fd, tmp = tempfile.mkstemp(dir=folder, prefix=prefix, suffix=suffix)
    os.fchmod(fd, 0o666 & ~_umask())
    return fd, tmp


def _remove(name) -> None:
    if name is not None and os.path.exists(name):
        os.unlink(name)


def write_atomic(path, write, flag: str = "output", mode: str = "w") -> Path:
    """Write a file atomically: ``write(f)`` on a temporary file in the target
    folder, renamed over ``path``. No temporary file is left behind, and an
    existing ``path`` stays as it was unless the write succeeds. A ``path``
    that is a device or a pipe is written in place.

    If writing fails (disk full, file size limit, folder removed meanwhile,
    ...), the same content is written to :func:`fallback_path` and a
    :class:`PanelDeployError` names ``flag``, the reason and where the content
    is, so nothing computed is lost; a fallback file that fails too is removed.
    """
    path = output_target(path)
    text = {} if "b" in mode else {"encoding": "utf-8"}
    tmp = None
    try:
        if in_place(path):
            with open(path, mode, **text) as f:
                write(f)
            return path
        fd, tmp = temporary_beside(path, f".{path.name}.", ".part")
        with os.fdopen(fd, mode, **text) as f:
            write(f)
        os.replace(tmp, path)
        return path
    except OSError as e:
        _remove(tmp)
        reason = e.strerror or str(e)
        rescue = None
        try:
            rescue = fallback_path(path)
            with open(rescue, mode, **text) as f:
                write(f)
        except OSError as e2:
            _remove(rescue)  # a partial file would look like a result
            raise PanelDeployError(f"{flag}: cannot write {path} ({reason}), nor a fallback "
                                   f"file ({e2.strerror or e2}); the result is lost") from None
        raise PanelDeployError(f"{flag}: cannot write {path} ({reason}); the result is saved "
                               f"in {rescue}") from None
    except BaseException:
        _remove(tmp)
        raise


def save_figure(fig, path, flag: str = "--plot", dpi: int = 120) -> Path:
    """A matplotlib figure written with :func:`write_atomic`, in the format of
    the file name's suffix (PNG if it has none)."""
    fmt = Path(path).suffix.lstrip(".").lower() or "png"
    return write_atomic(path, lambda f: fig.savefig(f, dpi=dpi, format=fmt), flag, mode="wb")


def first_non_finite(a) -> tuple | None:
    """Index (tuple) of the first NaN or inf of array ``a``, or None."""
    a = np.asarray(a)
    if a.dtype.kind not in "fc":
        return None
    bad = ~np.isfinite(a)
    if not bad.any():
        return None
    return tuple(int(i) for i in np.unravel_index(int(np.argmax(bad)), a.shape))


def check_finite(name: str, a, where: str = "", error=PanelDeployError):
    """Raise ``error`` naming ``where``, ``name`` and the first NaN/inf index of ``a``."""
    idx = first_non_finite(a)
    if idx is not None:
        value = np.asarray(a)[idx]
        index = ", ".join(map(str, idx))
        raise error(f"{where + ': ' if where else ''}{name}[{index}] is {value} "
                    "(expected finite values)")
    return a


def finite_number(value, flag: str, *, low=None, high=None, low_open=False, integer=False):
    """A flag's number checked: finite, within [low, high] (low open if asked),
    integral if asked; :class:`SceneError` naming ``flag`` otherwise."""
    if value is None:
        return None
    kind = "an integer" if integer else "a number"
    if isinstance(value, bool) or not isinstance(value, (int, float)) or \
            (integer and not isinstance(value, int) and not float(value).is_integer()):
        raise SceneError(flag, f"expected {kind}, got {shown(value)}")
    if isinstance(value, int) and abs(value) > 2 ** 1023:  # beyond any float: math would raise
        raise SceneError(flag, f"expected a finite number, got {shown(value)}")
    if not math.isfinite(value):
        raise SceneError(flag, f"expected a finite number, got {value}")
    if low is not None and (value <= low if low_open else value < low):
        raise SceneError(flag, f"expected {kind} {'>' if low_open else '>='} {low:g}, got {shown(value)}")
    if high is not None and value > high:
        raise SceneError(flag, f"expected {kind} <= {high:g}, got {shown(value)}")
    return value


def first_non_finite_value(value, path: str = "") -> str | None:
    """Key path (``collision.v``, ``final_angles.h1``) of the first NaN/inf
    float in a JSON-like value (dicts, lists, numbers), or None."""
    if isinstance(value, float):
        return None if math.isfinite(value) else f"{path or 'value'} = {value}"
    if isinstance(value, dict):
        items = value.items()
    elif isinstance(value, (list, tuple)):
        items = ((f"[{i}]", v) for i, v in enumerate(value))
    else:
        return None
    for key, v in items:
        if isinstance(v, (float, dict, list, tuple)):
            sub = f"{path}{key}" if str(key).startswith("[") else (f"{path}.{key}" if path else str(key))
            bad = first_non_finite_value(v, sub)
            if bad is not None:
                return bad
    return None
