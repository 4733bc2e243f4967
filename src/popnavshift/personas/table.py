"""The ``personas`` table's declaration (:mod:`popnavshift.tables`), made here because
its columns are the persona fields: the table layer knows no persona vocabulary, and
importing this module registers the table (:mod:`popnavshift.dictionary` does, and
every persona source)."""

from __future__ import annotations

from ..tables import Column, declare
from .fields import OPTIONAL_FIELDS, REQUIRED_FIELDS, field_catalog


def _persona_columns() -> tuple[Column, ...]:
    def field(name: str, nullable: bool) -> Column:
        spec = field_catalog()[name]
        values = ", ".join(spec["values"])
        missing = "the source record lacks the field" if nullable else ""
        return Column(name, "str", nullable, doc=f"{spec['label']}: one of {values}",
                      missing=missing)

    return (
        Column("persona_id", "str", doc="persona id: syn-NNNNNN (synthetic), the table's id, "
               "or source:source_record_id (MatrAIx release)"),
        Column("source", "str", doc="where the record comes from: synthetic, the table's "
               "file name, or the release record's source (gss, wiki, …)"),
        *(field(f, False) for f in REQUIRED_FIELDS),
        *(field(f, True) for f in OPTIONAL_FIELDS),
    )


PERSONAS = declare("personas", _persona_columns(), ("persona_id",),
                   doc="one persona record sampled from the persona source")
