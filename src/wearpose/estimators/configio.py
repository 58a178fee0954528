"""The dict round trip every estimator config shares (checkpoints store ``config.to_dict()``)."""

from __future__ import annotations

from dataclasses import asdict, fields, replace
from typing import Any, Callable, Self

from wearpose.errors import ConfigError


class ConfigIO:
    """Mixin for a method's config dataclass: ``to_dict`` / ``from_dict`` / ``override``.

    Subclasses holding tuples set ``TUPLE_FIELDS = {name: element_type_or_None}``: those fields
    are lists in the dict (JSON has no tuples) and tuples again after ``from_dict`` (elements
    converted by the type when given).
    """

    TUPLE_FIELDS: dict[str, Callable[[Any], Any] | None] = {}

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)  # type: ignore[call-overload]
        for k in self.TUPLE_FIELDS:
            d[k] = list(d[k])
        return d

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> Self:
        """The config of ``d`` (ConfigError naming unknown fields and the known ones)."""
        known = {f.name for f in fields(cls)}  # type: ignore[arg-type]
        unknown = sorted(set(d) - known)
        if unknown:
            raise ConfigError(f"{cls.__name__}: unknown fields {unknown}; known: {sorted(known)}")
        d = dict(d)
        for k, conv in cls.TUPLE_FIELDS.items():
            if k in d:
                d[k] = tuple(conv(v) for v in d[k]) if conv is not None else tuple(d[k])
        return cls(**d)

    def override(self, **kw: Any) -> Self:
        """A copy with the non-None keyword values replaced."""
        return replace(self, **{k: v for k, v in kw.items() if v is not None})  # type: ignore[type-var]
