"""The one rule for names that become paths (homocal.names)."""
import pytest

from homocal.names import MAX_NAME_LENGTH, check_name


@pytest.mark.parametrize("name", ["scene1", "a", "MOT17-02", "det_rgb.v2", "x" * MAX_NAME_LENGTH, "_x", "-x"])
def test_good_names_pass_unchanged(name):
    assert check_name(name) == name


@pytest.mark.parametrize("name", [
    "", ".", "..", ".hidden", "../x", "a/b", "a\\b", "/abs", "x" * (MAX_NAME_LENGTH + 1), "a\nb", "a b",
    "a\x00b", "é", None, 3, b"scene1", ["scene1"]])
def test_bad_names_are_one_line_naming_what(name):
    with pytest.raises(ValueError) as e:
        check_name(name, "sequence name")
    message = str(e.value)
    assert message.startswith("sequence name ") and "\n" not in message
    assert len(message) < 200
