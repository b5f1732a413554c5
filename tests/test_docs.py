"""docs/scene-format.md stays true (issue 10): every key the parser accepts is documented in its
table's section, every documented key is accepted, the example scene parses (and means what its
comments say), and the messages that send users to the schema name the file that exists."""

from __future__ import annotations

import re
import shutil
from pathlib import Path

import numpy as np
import pytest

from rtreflect.exchange.scene import MODE_KEYS, RENDER_MODES, SCHEMA_DOC, TABLE_KEYS, load_scene

ROOT = Path(__file__).resolve().parent.parent
REFERENCE = ROOT / "docs" / "scene-format.md"
SECTIONS = ("image", "camera", "lights", "surface", "render", "output")


def section(table: str) -> str:
    """The text of the reference's ``### `[table]` `` (or ``[[table]]``) section."""
    text = REFERENCE.read_text()
    found = re.search(rf"^### `\[\[?{table}\]\]?`.*?$(.*?)(?=^##)", text, re.S | re.M)
    assert found, f"no section for [{table}] in {REFERENCE}"
    return found[1]


def documented_keys(table: str) -> set[str]:
    """Keys in the first column of the section's key tables."""
    return set(re.findall(r"^\| `([a-z_]+)` \|", section(table), re.M))


def test_schema_doc_is_the_reference() -> None:
    assert (ROOT / SCHEMA_DOC).resolve() == REFERENCE and REFERENCE.is_file()
    assert "docs/scene-format.md" in (ROOT / "README.md").read_text()


@pytest.mark.parametrize("table", SECTIONS)
def test_every_key_the_parser_accepts_is_documented_and_no_other(table: str) -> None:
    assert documented_keys(table) == set(TABLE_KEYS[table])


def test_every_top_level_table_has_a_section() -> None:
    assert set(TABLE_KEYS[""]) == set(SECTIONS)
    for table in SECTIONS:
        section(table)


def circle_examples() -> list[str]:
    """The ``[lights]`` tables of "The other modes" (circles), each parsed in place of the example's."""
    text = re.search(r"^## The other modes$(.*?)(?=^## )", REFERENCE.read_text(), re.S | re.M)[1]
    return re.findall(r"```toml\n(\[lights\]\n.*?)```", text, re.S)


def mode_examples() -> list[str]:
    """The ``[render]`` tables of "The other modes": one per mode besides reflection."""
    text = re.search(r"^## The other modes$(.*?)(?=^## )", REFERENCE.read_text(), re.S | re.M)[1]
    found = re.findall(r"```toml\n(\[render\]\n.*?)```", text, re.S)
    assert sorted(re.search(r'^mode = "(\w+)"', block, re.M)[1] for block in found) == sorted(RENDER_MODES[1:])
    return found


def test_example_scene_parses_and_means_what_it_says(tmp_path: Path) -> None:
    example = re.search(r"^## Example$.*?```toml\n(.*?)```", REFERENCE.read_text(), re.S | re.M)[1]
    (tmp_path / "example.toml").write_text(example)
    shutil.copy(ROOT / "scenes" / "teapot.bpt", tmp_path / "teapot.bpt")
    scene = load_scene(tmp_path / "example.toml")
    # Every table and key of the parser is used by the example (a reader sees them all once); the keys
    # of the modes other than reflection by the examples of those modes, each parsed in place of [render].
    modes = mode_examples()
    for render in modes:
        (tmp_path / "mode.toml").write_text(re.sub(r"^\[render\]\n(?:[a-z_]+ = .*\n)*", render, example, flags=re.M))
        assert load_scene(tmp_path / "mode.toml").render.mode in render
    # The circles' keys by the examples of circles, each parsed in place of [lights] (with a mode that sees circles).
    circles = circle_examples()
    assert circles
    for lights in circles:
        text = re.sub(r"^\[lights\]\n(?:[a-z_]+ = .*\n)*", lights, example, flags=re.M)
        (tmp_path / "circles.toml").write_text(text)
        assert load_scene(tmp_path / "circles.toml").lights.shape == "circles"
    for table, keys in TABLE_KEYS.items():
        if table:
            for key in keys:
                if not (table == "lights" and key == "positions"):  # spacing/count stand for it
                    shown = example if not (table == "render" and key in MODE_KEYS) else "".join(modes)
                    shown += "".join(circles) if table == "lights" else ""
                    assert re.search(rf"^{key} = ", shown, re.M), f"{table}.{key} not in the example"
    # spacing/count are centred on Q, as the comments and the [lights] section say.
    assert np.allclose(scene.lights.positions, np.arange(-2.0, 2.01, 0.5))
    assert np.allclose(np.cross(scene.lights.direction, scene.lights.normal), [1.0, 0.0, 0.0])  # e = +x
    assert "c_k = (k − (count − 1)/2) · spacing" in section("lights")
    assert scene.output.name == "bump" and len(scene.surfaces) == 1 + 32  # the bump and the teapot's patches


def test_unknown_key_message_points_to_the_reference(tmp_path: Path) -> None:
    from rtreflect.errors import SceneError

    text = (ROOT / "scenes" / "hood.toml").read_text()
    (tmp_path / "a.toml").write_text(text.replace("[render]", "[render]\nzzz_unrelated = 1", 1))
    with pytest.raises(SceneError, match=re.escape(f"render.zzz_unrelated: unknown key; see {SCHEMA_DOC}")):
        load_scene(tmp_path / "a.toml")
    (tmp_path / "b.toml").write_text(text.replace("radius = 0.05", "raduis = 0.05", 1))
    with pytest.raises(SceneError, match=re.escape("lights.raduis: unknown key; did you mean radius?")):
        load_scene(tmp_path / "b.toml")


def test_a_table_nested_in_another_is_named_as_such(tmp_path: Path) -> None:
    from rtreflect.errors import SceneError

    text = (ROOT / "scenes" / "hood.toml").read_text().replace("[lights]", "[camera.lights]", 1)
    (tmp_path / "a.toml").write_text(text)
    with pytest.raises(SceneError) as error:
        load_scene(tmp_path / "a.toml")
    assert getattr(error.value, "errors", [error.value]) == [error.value]  # "lights missing" follows: not repeated
    assert str(error.value) == f"{tmp_path / 'a.toml'}: camera.lights: unknown key; [lights] is a table of its own, " \
                               f"not a key of [camera]"
