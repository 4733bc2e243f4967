"""A study file's YAML, read strictly: ``safe_load`` that refuses a key given twice.

Plain YAML keeps the last of two equal keys silently, so a second ``seeds:`` would
quietly replace the first; here it is an error naming the key and its line.
"""

from __future__ import annotations

from typing import Any

import yaml

from ..errors import ConfigError


class _DuplicateKey(Exception):
    def __init__(self, key: Any, line: int) -> None:
        self.key, self.line = key, line


class _StudyLoader(yaml.SafeLoader):
    """safe_load that refuses a key given twice in one mapping (plain YAML keeps the
    last one silently, so a second ``seeds:`` would quietly replace the first)."""

    def construct_mapping(self, node, deep=False):
        seen: set[Any] = set()
        for key_node, _ in node.value:
            if key_node.tag == "tag:yaml.org,2002:merge":
                continue
            key = self.construct_object(key_node, deep=True)
            try:
                if key in seen:
                    raise _DuplicateKey(key, key_node.start_mark.line + 1)
                seen.add(key)
            except TypeError:  # an unhashable key: safe_load's own error says so
                break
        return super().construct_mapping(node, deep=deep)


def parse_study_yaml(text: str, where: str) -> Any:
    """The YAML document of a study file, with one-line errors (syntax, duplicate key)."""
    try:
        return yaml.load(text, Loader=_StudyLoader)  # noqa: S506 - a SafeLoader subclass
    except _DuplicateKey as dup:
        raise ConfigError(f"{where}: key {dup.key!r} appears twice (line {dup.line})",
                          hint="keep one of them") from None
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        at = f" at line {mark.line + 1}" if mark else ""
        raise ConfigError(f"{where}: not valid YAML{at}") from None
