"""host/tools/generated_page.py: a generated block replaces only what lies
between its markers in a page people write the rest of."""

import importlib.util
from pathlib import Path

import pytest

BEGIN = "<!-- tool: writes from here on -->"
END = "<!-- /tool -->"


def _generated_page():
    spec = importlib.util.spec_from_file_location(
        "generated_page", Path(__file__).resolve().parents[1] / "tools" / "generated_page.py"
    )
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_a_block_is_replaced_between_its_markers(tmp_path):
    page = _generated_page()
    document = tmp_path / "page.md"
    document.write_text(f"before\n{BEGIN}\nold\n{END}\nafter\n")
    page.write_block(document, BEGIN, END, "new | 49/50")
    written = document.read_text()
    assert written == f"before\n{BEGIN}\n\nnew | 49/50\n{END}\nafter\n"


def test_a_new_page_holds_the_block_alone(tmp_path):
    page = _generated_page()
    elsewhere = tmp_path / "new" / "rates.md"
    page.write_block(elsewhere, BEGIN, END, "text")
    assert elsewhere.read_text() == f"{BEGIN}\n\ntext\n{END}\n"


def test_a_page_without_the_block_is_refused_and_kept(tmp_path):
    page = _generated_page()
    document = tmp_path / "page.md"
    document.write_text("no block\n")
    with pytest.raises(ValueError, match="has no"):
        page.write_block(document, BEGIN, END, "text")
    assert document.read_text() == "no block\n"
