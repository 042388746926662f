"""Every export format by name: the exporter class that writes it."""

from __future__ import annotations

from backend.exports.image_exporters import BopExporter, CocoExporter
from backend.exports.writers import CvatExporter, DexYCBExporter, Exporter, JsonExporter

EXPORTERS: dict[str, type[Exporter]] = {
    "dexycb": DexYCBExporter, "json": JsonExporter, "cvat": CvatExporter,
    "coco": CocoExporter, "bop": BopExporter,
}
