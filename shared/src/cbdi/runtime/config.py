"""Service configuration from flags, environment and a TOML file, validated by type.

Precedence, highest first: command-line flags, `CBDI_<FIELD>` environment variables, the
TOML file given with `--config` (top-level keys or a `[<section>]` table), the dataclass
defaults. Every bad value is a `ConfigError` naming its source and the field.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import re
import tomllib
import typing
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, TypeVar

import msgspec

from cbdi.errors import ConfigError
from cbdi.runtime.life import count_start

__all__ = ["load_config"]

T = TypeVar("T")
ENV_PREFIX = "CBDI_"


def _flag(name: str) -> str:
    return "--" + name.replace("_", "-")


def _origin_is_tuple(tp: Any) -> bool:
    return typing.get_origin(tp) in (tuple, list)


def _is_bool(tp: Any) -> bool:
    return tp is bool or tp == "bool"


def _parser(
    cls: type[Any], prog: str, description: str, positional: Sequence[str] = ()
) -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog=prog, description=description)
    parser.add_argument("--config", metavar="FILE", help="TOML file with settings")
    hints = typing.get_type_hints(cls)
    for f in dataclasses.fields(cls):
        tp = hints[f.name]
        help_text = f.metadata.get("help", "")
        default = f.default if f.default is not dataclasses.MISSING else None
        if default is not None and not _origin_is_tuple(tp):
            help_text = f"{help_text} (default: {default})".strip()
        if f.name in positional:
            parser.add_argument(f.name, nargs="?", default=None, help=help_text)
        elif _is_bool(tp):
            parser.add_argument(
                _flag(f.name),
                dest=f.name,
                action=argparse.BooleanOptionalAction,
                default=None,
                help=help_text,
            )
        elif _origin_is_tuple(tp):
            parser.add_argument(
                _flag(f.name),
                dest=f.name,
                action="append",
                default=None,
                help=help_text + " (repeatable)",
            )
        else:
            parser.add_argument(_flag(f.name), dest=f.name, default=None, help=help_text)
    return parser


def _from_file(path: str, section: str) -> dict[str, Any]:
    try:
        data = tomllib.loads(Path(path).read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise ConfigError(path, "--config", "file not found") from None
    except OSError as exc:
        raise ConfigError(path, "--config", exc.strerror or str(exc)) from None
    except UnicodeDecodeError as exc:
        raise ConfigError(path, "--config", f"not UTF-8 text (byte {exc.start})") from None
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(path, "toml", str(exc)) from None
    table = data.get(section, data)
    if not isinstance(table, dict):
        raise ConfigError(path, section, "expected a table")
    return {k.replace("-", "_"): v for k, v in table.items() if not isinstance(v, dict)}


def _from_env(cls: type[Any], env: Mapping[str, str]) -> dict[str, Any]:
    hints = typing.get_type_hints(cls)
    found: dict[str, Any] = {}
    for f in dataclasses.fields(cls):
        raw = env.get(ENV_PREFIX + f.name.upper())
        if raw is None:
            continue
        tp = hints[f.name]
        if _origin_is_tuple(tp):
            found[f.name] = [part for part in raw.split(",") if part]
        elif _is_bool(tp):
            found[f.name] = raw.strip().lower() in ("1", "true", "yes", "on")
        else:
            found[f.name] = raw
    return found


def load_config(
    cls: type[T],
    argv: Sequence[str] | None,
    *,
    prog: str,
    section: str,
    description: str = "",
    env: Mapping[str, str] | None = None,
    positional: Sequence[str] = (),
) -> T:
    """Parse `argv`, the environment and the optional TOML file into a `cls` dataclass.

    Fields named in `positional` are taken as positional arguments instead of flags.
    """
    if env is None:
        count_start()  # a container restarted by its policy learns its restart count
    parser = _parser(cls, prog, description, positional)
    args = parser.parse_args(list(argv) if argv is not None else None)
    sources: dict[str, str] = {}
    merged: dict[str, Any] = {}
    layers: list[tuple[str, dict[str, Any]]] = []
    if args.config:
        layers.append((f"config file {args.config}", _from_file(args.config, section)))
    layers.append(("environment", _from_env(cls, os.environ if env is None else env)))
    flags = {k: v for k, v in vars(args).items() if k != "config" and v is not None}
    layers.append(("command line", flags))
    known = {f.name for f in dataclasses.fields(cls)}  # type: ignore[arg-type]
    for source, values in layers:
        for key, value in values.items():
            if key not in known:
                raise ConfigError(
                    source, key, f"unknown setting (known: {', '.join(sorted(known))})"
                )
            merged[key] = value
            sources[key] = source
    return _convert(cls, merged, sources)


def _convert(cls: type[T], merged: dict[str, Any], sources: dict[str, str]) -> T:
    try:
        return msgspec.convert(merged, cls, strict=False)
    except msgspec.ValidationError as exc:
        text = str(exc)
        match = re.search(r"at `\$\.(\w+)", text)
        field = match.group(1) if match else "?"
        raise ConfigError(sources.get(field, "defaults"), field, text) from None
    except (TypeError, ValueError) as exc:  # a dataclass __post_init__ may validate too
        raise ConfigError("settings", "?", str(exc)) from None
