"""JSON Schemas of the report and of the handles file (issue 25, item 2)."""

from __future__ import annotations

import glob
import json
import os
from importlib.resources import files

import jsonschema
import pytest
from click.testing import CliRunner

from featurewarp_cli.cli.main import cli
from featurewarp_cli.engine.handles import Handles

SAMPLES = os.path.join(os.path.dirname(__file__), os.pardir, "samples")


def schema(kind: str) -> dict:
    return json.loads((files("featurewarp_cli") / "schemas" / f"{kind}.schema.json").read_text())


@pytest.mark.parametrize("kind", ["report", "handles"])
def test_the_schemas_are_draft_2020_12_and_printed_as_shipped(kind):
    jsonschema.Draft202012Validator.check_schema(schema(kind))
    printed = CliRunner().invoke(cli, ["schema", kind])
    assert printed.exit_code == 0 and json.loads(printed.output) == schema(kind)


@pytest.mark.parametrize("args", [
    ["warp", "swirl", "--angle", "120"],
    ["warp", "stretch", "--sx", "1.5", "--mode", "rigid"],
    ["warp", "arc", "--mode", "plain"],
    ["warp", "perspective", "--formulation", "paper"],
])
def test_reports_validate(tmp_path, args):
    report = tmp_path / "r.json"
    command = args[:2] + [os.path.join(SAMPLES, "shapes.png"), str(tmp_path / "o.png"), "-m",
                          os.path.join(SAMPLES, "shapes_mask.png"), "--report", str(report)] + args[2:]
    assert CliRunner().invoke(cli, command).exit_code == 0
    made = json.loads(report.read_text())
    assert made["schema"] == "featurewarp-report/3"
    jsonschema.validate(made, schema("report"))
    wrong = json.loads(json.dumps(made))       # the figures are typed: a text in their place fails
    wrong["quality"]["background_rms_px"] = "a figure"
    with pytest.raises(jsonschema.ValidationError):
        jsonschema.validate(wrong, schema("report"))
    assert bool(made["components"]["items"]) == (made["mode"] != "plain")     # plain: no component to check
    for item in wrong["components"]["items"][:1]:
        wrong["quality"] = made["quality"]
        item["anisotropy_worst"] = "a figure"
        with pytest.raises(jsonschema.ValidationError):
            jsonschema.validate(wrong, schema("report"))


def test_handles_files_validate_and_bad_ones_do_not():
    validator = jsonschema.Draft202012Validator(schema("handles"))
    samples = glob.glob(os.path.join(SAMPLES, "*handles*.json"))
    assert samples
    for path in samples:
        with open(path) as f:
            data = json.load(f)
        validator.validate(data)
        validator.validate(Handles.from_dict(data, 512, 512).as_dict())      # what edit saves
    for bad in ({"version": 3}, {"version": 1, "points": [{"from": [1, 2]}]},
                {"version": 1, "border": "loose"}, {"version": 1, "canvas": "big"},
                {"version": 1, "curves": [{"from": [[1, 2]], "to": [[1, 2], [3, 4]]}]},
                {"version": 1, "border": {}}, {"version": 1, "border": {"middle": [[0, 0], [1, 1]]}},
                {"version": 1, "radius": -1}):
        assert not validator.is_valid(bad), bad
    assert validator.is_valid({"version": 1, "radius": 0})                 # a handle that holds its point only


def test_the_handles_file_is_checked_through_its_schema(monkeypatch):
    """Handles.from_dict asks the shipped schema: a rule added there is enforced at once."""
    from featurewarp_cli import schema as shipped

    strict = json.loads(shipped.text("handles"))
    strict["properties"]["canvas"] = {"enum": ["input"], "title": "only \"input\" (a test schema)"}
    monkeypatch.setattr(shipped, "text", lambda kind: json.dumps(strict))
    shipped.validator.cache_clear()
    try:
        with pytest.raises(ValueError, match=r'^canvas: expected only "input" \(a test schema\), got "fit"$'):
            Handles.from_dict({"version": 1, "canvas": "fit", "border": "pinned"}, 64, 48)
    finally:
        monkeypatch.undo()
        shipped.validator.cache_clear()
    assert Handles.from_dict({"version": 1, "canvas": "fit", "border": "pinned"}, 64, 48).canvas == "fit"


def test_deform_reports_document_how_far_each_handle_ended(tmp_path):
    """Deform trial, finding 4: params was a free object, so handle_error_px and curve_error_px
    were not described; they and the per-handle list (handle_ends) are, and typed."""
    report, handles = tmp_path / "r.json", tmp_path / "h.json"
    handles.write_text(json.dumps({"version": 1, "curves": [{"from": [[20, 200], [120, 200]],
                                                             "to": [[20, 210], [120, 210]]}]}))
    run = CliRunner().invoke(cli, ["deform", os.path.join(SAMPLES, "shapes.png"), str(tmp_path / "o.png"),
                                   "--handles", str(handles), "--pin", "10,10", "--move", "300,100:310,90",
                                   "--report", str(report)])
    assert run.exit_code == 0, run.output
    made = json.loads(report.read_text())
    jsonschema.validate(made, schema("report"))
    assert [e["given"] for e in made["params"]["handle_ends"]] == ["--move 300,100:310,90", "--pin 10,10"]
    assert made["params"]["curve_ends"][0]["given"] == "curves[0]"
    described = schema("report")["properties"]["params"]["properties"]
    assert {"handle_error_px", "curve_error_px", "handle_ends", "curve_ends"} <= set(described)
    for key, wrong in (("handle_error_px", {"max": "far"}), ("handle_ends", [{"given": "x"}])):
        broken = json.loads(json.dumps(made))
        broken["params"][key] = wrong
        with pytest.raises(jsonschema.ValidationError):
            jsonschema.validate(broken, schema("report"))


def test_the_handles_schema_says_unknown_keys_are_warned():
    """Deform trial, nit 8: the schema said 'ignored, with a note'; it is a warning --strict refuses."""
    assert "with a note" not in json.dumps(schema("handles"))


def test_output_and_refused_come_in_one_of_their_two_forms(tmp_path):
    """A report with neither an output nor a refusal, or with both, validated (review finding 11):
    the schema ties output null to a refused object, and an output to refused null or absent
    (reports of earlier versions have no refused)."""
    report = tmp_path / "r.json"
    run = CliRunner().invoke(cli, ["warp", "swirl", os.path.join(SAMPLES, "shapes.png"), str(tmp_path / "o.png"),
                                   "--report", str(report)])
    assert run.exit_code == 0
    written = json.loads(report.read_text())
    assert written["refused"] is None and isinstance(written["output"], dict)
    refused = written | {"output": None, "refused": {"error": "--strict: a warning; nothing written but the report",
                                                     "warnings": ["a warning"]}}
    earlier = {key: value for key, value in written.items() if key != "refused"}
    for good in (written, refused, earlier):
        jsonschema.validate(good, schema("report"))
    neither = refused | {"refused": None}
    both = written | {"refused": refused["refused"]}
    unsaid = {key: value for key, value in refused.items() if key != "refused"}
    for bad in (neither, both, unsaid):
        with pytest.raises(jsonschema.ValidationError):
            jsonschema.validate(bad, schema("report"))
