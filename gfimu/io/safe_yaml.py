"""YAML from users' files, parsed with bounds: pyyaml's safe loader behind a check of nesting depth and alias
expansion (a few hundred bytes of nested aliases stand for billions of nodes), refusing duplicate keys, and
reading OpenCV FileStorage's ``%YAML:1.0`` first line and ``!!opencv-matrix`` nodes. Used by the Kalibr
extrinsics (``--extrinsics``) and for a ROS 2 bag's ``metadata.yaml``; pyyaml is imported only when called.
"""

from __future__ import annotations

import re
from pathlib import Path

from .errors import LogFormatError
from ..errors import MissingExtraError

MAX_YAML_DEPTH = 64  # nesting of collections; a Kalibr chain needs 3
MAX_YAML_NODES = 200_000  # nodes once every alias is expanded; a Kalibr chain of 8 IMUs has about 300
OPENCV_DIRECTIVE = re.compile(r"%YAML:\d+\.\d+")  # OpenCV FileStorage's first line, which YAML 1.1 does not allow


class OpenCVMatrix(dict):
    """A ``!!opencv-matrix`` node (rows, cols, dt, data) as OpenCV's FileStorage writes it; ``line`` 1-based."""

    line: int = 0


def _yaml_module(path: Path, extra: str = "kalibr"):
    try:
        import yaml
    except ImportError:
        raise MissingExtraError(f"{path}: reading YAML", "pyyaml", extra) from None
    return yaml


def check_yaml_size(yaml, text: str, path: Path) -> None:
    """Refuse, before anything is built, a document nested deeper than ``MAX_YAML_DEPTH`` or whose aliases
    expand to more than ``MAX_YAML_NODES`` nodes (nested aliases grow exponentially: a few hundred bytes can
    stand for billions of nodes) or refer to a node that contains them. One pass over the parser's events,
    which pyyaml produces without recursion."""
    sizes: dict[str, int] = {}  # anchor -> nodes of its node, aliases expanded
    stack: list[list] = []  # open collections: [nodes so far, anchor]
    aliases = 0  # alias events seen: without any, a document too large is large, not an alias bomb
    for event in yaml.parse(text, Loader=yaml.SafeLoader):
        if isinstance(event, (yaml.SequenceStartEvent, yaml.MappingStartEvent)):
            if len(stack) >= MAX_YAML_DEPTH:
                raise LogFormatError(f"nested deeper than {MAX_YAML_DEPTH} levels (a calibration or bag metadata "
                                     "needs a few); not read", path, event.start_mark.line + 1)
            stack.append([1, event.anchor])
            continue
        if isinstance(event, (yaml.SequenceEndEvent, yaml.MappingEndEvent)):
            n, anchor = stack.pop()
        elif isinstance(event, yaml.ScalarEvent):
            n, anchor = 1, event.anchor
        elif isinstance(event, yaml.AliasEvent):
            if event.anchor not in sizes:
                raise LogFormatError(f"alias *{event.anchor} refers to a node that contains it (or to no anchor): "
                                     "not read", path, event.start_mark.line + 1)
            n, anchor = sizes[event.anchor], None
            aliases += 1
        else:
            continue
        if anchor is not None:
            sizes[anchor] = n
        if stack:
            stack[-1][0] += n
            if stack[-1][0] > MAX_YAML_NODES:
                break
        elif n > MAX_YAML_NODES:
            break
    else:
        return
    if not aliases:
        raise LogFormatError(f"holds more than {MAX_YAML_NODES} values (a calibration or a bag's metadata has a few "
                             "hundred): not read; is it the right file?", path, event.start_mark.line + 1)
    raise LogFormatError(f"its aliases (*name) expand to more than {MAX_YAML_NODES} nodes (nested aliases, a "
                         "'billion laughs' document?); a calibration or a bag's metadata has a few hundred: not read",
                         path, event.start_mark.line + 1)


def _safe_loader(yaml, path: Path):
    """pyyaml's SafeLoader that refuses duplicate keys and reads ``!!opencv-matrix`` nodes."""

    class Loader(yaml.SafeLoader):
        def construct_mapping(self, node, deep=False):
            seen: dict = {}
            for key_node, _ in node.value:
                if key_node.tag == "tag:yaml.org,2002:merge":
                    continue
                key = self.construct_object(key_node, deep=True)
                try:
                    first = seen.setdefault(key, key_node.start_mark.line + 1)
                except TypeError:
                    raise LogFormatError(f"a key that is not a name ({key!r})", path,
                                         key_node.start_mark.line + 1) from None
                if first != key_node.start_mark.line + 1:
                    raise LogFormatError(f"{key}: given twice (lines {first} and {key_node.start_mark.line + 1}); "
                                         "which one is meant is unknown", path, key_node.start_mark.line + 1, str(key))
            return super().construct_mapping(node, deep=deep)

    def opencv_matrix(loader, node):
        if not isinstance(node, yaml.MappingNode):
            raise LogFormatError("!!opencv-matrix: expected rows, cols, dt and data", path, node.start_mark.line + 1)
        m = OpenCVMatrix(loader.construct_mapping(node, deep=True))
        m.line = node.start_mark.line + 1
        return m

    Loader.add_constructor("tag:yaml.org,2002:opencv-matrix", opencv_matrix)
    return Loader


def load_yaml(path: Path, what: str = "a Kalibr YAML file", extra: str = "kalibr"):
    """(document, text) of a YAML file (an OpenCV one too); its depth and aliases bounded first. LogFormatError
    naming the file (and line) for anything wrong; ``what`` names the file expected in messages, ``extra`` the
    extra that installs pyyaml for it (MissingExtraError without pyyaml)."""
    yaml = _yaml_module(path, extra)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise LogFormatError("file not found", path) from None
    except IsADirectoryError:
        raise LogFormatError(f"is a folder, expected {what}", path) from None
    except UnicodeDecodeError as exc:
        raise LogFormatError(f"not UTF-8 text (byte {exc.start})", path) from None
    first, newline, rest = text.partition("\n")
    if OPENCV_DIRECTIVE.match(first.lstrip("\ufeff")):
        text = "#" + first + newline + rest  # the directive as a comment: line numbers stay
    try:
        check_yaml_size(yaml, text, path)
        loader = _safe_loader(yaml, path)(text)
        try:
            return loader.get_single_data(), text
        finally:
            loader.dispose()
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        problem = getattr(exc, "problem", None) or str(exc).splitlines()[0]
        raise LogFormatError(f"not valid YAML: {problem}", path, None if mark is None else mark.line + 1) from None
    except RecursionError:  # not reached after _check_yaml_size; kept so that no traceback escapes
        raise LogFormatError("nested too deeply to read", path) from None
