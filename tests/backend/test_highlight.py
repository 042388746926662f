"""The object highlight's label: the name the annotation page calls the object by."""

from __future__ import annotations

from backend.annotation.highlight import object_label


def test_object_label_drops_the_ycb_number_and_underscores() -> None:
    assert object_label("025_mug") == "mug"
    assert object_label("006_mustard_bottle") == "mustard bottle"
    assert object_label("011_banana") == "banana"


def test_object_label_keeps_names_without_a_number() -> None:
    assert object_label("red_cup") == "red cup"
    assert object_label("mug") == "mug"
    assert object_label("007_") == "007"
    assert object_label("_") == "object"
