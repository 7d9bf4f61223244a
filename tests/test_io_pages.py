"""Published results: a page's marked section replaced in place, once; a result record read back whole or
refused in one line naming it."""

import pytest

from rheograph.errors import InputError
from rheograph.io.pages import read_record, render_blocks, replace_section, table_block, write_record


def test_a_marked_section_is_replaced_in_place_and_the_rest_of_the_page_kept(tmp_path):
    page = tmp_path / "page.md"
    page.write_text("# T\n\nbefore\n\n<!-- s:start -->\nold\n<!-- s:end -->\n\nafter\n")
    replace_section(page, "s", "new")
    assert page.read_text() == "# T\n\nbefore\n\n<!-- s:start -->\nnew\n<!-- s:end -->\n\nafter\n"
    replace_section(page, "t", "appended")  # markers absent, no heading to go before: appended
    assert page.read_text().endswith("after\n\n<!-- t:start -->\nappended\n<!-- t:end -->\n")
    assert not list(tmp_path.glob("*.tmp"))


def test_a_record_round_trips_and_a_damaged_one_is_one_line(tmp_path):
    path = tmp_path / "records" / "x.json"
    write_record(path, {"command": "python -m bench.x", "values": [0.5, float("nan")]})
    record = read_record(path, "result record of x")
    assert record["command"] == "python -m bench.x" and record["values"][0] == 0.5
    path.write_text("[1, 2]")
    with pytest.raises(InputError, match="x.json: not a result record of x"):
        read_record(path, "result record of x")
    path.write_text('{"cut')
    with pytest.raises(InputError, match="x.json: not a readable result record of x"):
        read_record(path, "result record of x")


def test_blocks_render_prose_verbatim_and_tables_cell_for_cell():
    blocks = [
        {"text": "Title\n"},
        table_block(["a", "b"], [[1, ""], ["x", 0.5]], align=["---", "--:"]),
        {"text": "\nCommand: `python -m bench.x`"},
    ]
    assert (
        render_blocks(blocks)
        == "Title\n\n| a | b |\n|---|--:|\n| 1 | |\n| x | 0.5 |\n\nCommand: `python -m bench.x`"
    )


def test_an_indented_table_renders_inside_its_list_item():
    blocks = [{"text": "* item"}, table_block(["a"], [[1]], indent="  ")]
    assert render_blocks(blocks) == "* item\n  | a |\n  |---|\n  | 1 |"
    assert "indent" not in table_block(["a"], [[1]])["table"]  # records without one keep their old form
