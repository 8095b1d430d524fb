"""The one schema library: each way a document can be wrong is one line naming the file,
the key as the file spells it, the value and what was expected."""

import json
from enum import StrEnum
from typing import Annotated, Literal

import pytest
from pydantic import Field

from hil_config import (
    FieldError,
    Number,
    Positive,
    PositiveInteger,
    Text,
    Vector3,
    json_schema,
    parse,
    table,
)


class Colour(StrEnum):
    RED = "red"
    BLUE = "blue"


@table
class Inner:
    rate_hz: PositiveInteger = 100
    offset_m: Vector3 = (0.0, 0.0, 0.0)

    def __post_init__(self) -> None:
        if 1000 % self.rate_hz:
            raise FieldError("rate_hz", self.rate_hz, "must divide 1000")


@table(kw_only=True)
class Step:
    at_s: Number
    action: Literal["step"] = "step"
    size: Positive


@table(kw_only=True)
class Hold:
    at_s: Number
    action: Literal["hold"] = "hold"


@table
class Outer:
    name: Text
    colour: Colour = Colour.RED
    inner: Inner = Inner()
    steps: tuple[Annotated[Step | Hold, Field(discriminator="action")], ...] = ()


class DocError(ValueError):
    pass


def _error(document) -> str:
    with pytest.raises(DocError) as caught:
        parse(Outer, document, "f.toml", DocError)
    return str(caught.value)


def test_a_good_document_becomes_typed_tables_with_the_defaults():
    document = {"name": "a", "colour": "blue", "inner": {"offset_m": [1, 2, 3]},
                "steps": [{"action": "step", "at_s": 1, "size": 2}]}  # fmt: skip
    outer = parse(Outer, document, "f", DocError)
    step = Step(at_s=1.0, size=2.0)
    assert outer == Outer("a", Colour.BLUE, Inner(100, (1.0, 2.0, 3.0)), (step,))
    assert isinstance(outer.inner.offset_m[0], float)


@pytest.mark.parametrize(
    ("document", "line"),
    [
        ({}, "f.toml: key 'name' is missing"),
        ({"name": ""}, "f.toml: key 'name' = '': expected at least 1 item(s)"),
        ({"name": "a", "nme": 1}, "f.toml: key 'nme' = 1: unknown key"),
        ({"name": "a", "colour": "green"},
         "f.toml: key 'colour' = 'green': expected 'red' or 'blue'"),
        ({"name": "a", "inner": {"rate_hz": "5"}},
         "f.toml: key 'inner.rate_hz' = '5': expected a valid integer"),
        ({"name": "a", "inner": {"rate_hz": 5.0}},
         "f.toml: key 'inner.rate_hz' = 5.0: expected a valid integer"),
        ({"name": "a", "inner": {"rate_hz": True}},
         "f.toml: key 'inner.rate_hz' = True: expected a valid integer"),
        ({"name": "a", "inner": {"rate_hz": 0}},
         "f.toml: key 'inner.rate_hz' = 0: expected a value > 0"),
        ({"name": "a", "inner": {"rate_hz": 3}},
         "f.toml: key 'inner.rate_hz' = 3: must divide 1000"),
        ({"name": "a", "inner": {"offset_m": [1, 2]}},
         "f.toml: key 'inner.offset_m[2]' is missing"),
        ({"name": "a", "inner": {"offset_m": [1, 2, float("nan")]}},
         "f.toml: key 'inner.offset_m[2]' = nan: expected a finite number"),
        ({"name": "a", "inner": 5},
         "f.toml: key 'inner' = 5: expected a dictionary or an instance of Inner"),
        ({"name": "a", "steps": [{"action": "hold", "at_s": 0},
                                 {"action": "step", "at_s": 1, "size": -1}]},
         "f.toml: key 'steps[1].size' = -1: expected a value > 0"),
        ({"name": "a", "steps": [{"action": "hold", "at_s": 0, "size": 1}]},
         "f.toml: key 'steps[0].size' = 1: unknown key"),
        ({"name": "a", "steps": [{"action": "jump", "at_s": 0}]},
         "f.toml: key 'steps[0].action' = 'jump': expected one of 'step', 'hold'"),
        ({"name": "a", "steps": [{"at_s": 0}]}, "f.toml: key 'steps[0].action' is missing"),
    ],
)  # fmt: skip
def test_each_problem_is_one_line_naming_key_value_and_expectation(document, line):
    assert _error(document) == line


def test_the_json_schema_carries_types_bounds_enums_defaults_and_refuses_unknown_keys():
    schema = json_schema(Outer)
    json.dumps(schema)  # plain JSON
    inner = schema["$defs"]["Inner"]
    assert inner["additionalProperties"] is False
    assert inner["properties"]["rate_hz"] == {
        "default": 100, "exclusiveMinimum": 0, "title": "Rate Hz", "type": "integer"
    }  # fmt: skip
    assert schema["$defs"]["Colour"]["enum"] == ["red", "blue"]
    assert schema["required"] == ["name"]


@table
class Documented:
    """A table whose fields say what they are."""

    #: The vehicle's mass,
    #: without the battery.
    mass_kg: Positive
    count: PositiveInteger = 1  # a trailing remark is not documentation
    #: Not about the next line.

    #: Where the centre of mass sits.
    centre_m: Vector3 = (0.0, 0.0, 0.0)

    def scaled(self, factor: float) -> float:
        #: inside a method: no field's comment
        return self.mass_kg * factor


@table(kw_only=True)
class MoreDocumented(Documented):
    #: When it starts.
    at_s: Number = 0.0


def test_a_fields_doc_comment_is_its_description_in_the_json_schema():
    """``#:`` lines above a field (joined) describe it, for an editor's hover and the
    configuration reference; a trailing remark, a comment cut off by a blank line's field
    or one inside a method describes nothing; a table that extends another keeps them."""
    properties = json_schema(Documented)["properties"]
    assert properties["mass_kg"]["description"] == "The vehicle's mass, without the battery."
    assert "description" not in properties["count"]
    assert properties["centre_m"]["description"] == "Where the centre of mass sits."
    extended = json_schema(MoreDocumented)["properties"]
    assert extended["at_s"]["description"] == "When it starts."
    assert extended["mass_kg"]["description"] == "The vehicle's mass, without the battery."
