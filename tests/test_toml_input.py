"""Every gfimu TOML input (array.toml, a CSV column map, calibration.toml) is loaded by one reader
(gfimu.io.toml_input.load_toml): a syntax error is one line naming the file and its line, whichever input it is."""

import pytest

from gfimu.calibration import CalibrationFileError, read_calibration
from gfimu.io import parse_array_toml
from gfimu.io.errors import LogFormatError
from gfimu.io.readers.csv.column_map import parse_map
from gfimu.io.toml_input import load_toml

UNCLOSED = "position = [0.1, 0\nname = 'x'\n"  # an array not closed: tomllib names the line after it


def test_load_toml_gives_the_document_and_the_line_of_each_key(tmp_path):
    doc, ctx = load_toml('format = "x"\n\n[[accelerometers]]\nname = "a"\n[[accelerometers]]\nname = "b"\n',
                         tmp_path / "f.toml")
    assert doc == {"format": "x", "accelerometers": [{"name": "a"}, {"name": "b"}]}
    err = ctx.error("expected something else", "accelerometers", 1, "name")
    assert str(err) == f"{tmp_path / 'f.toml'}:6: accelerometers[1].name: expected something else"
    assert (err.line, err.key) == (6, "accelerometers[1].name")


@pytest.mark.parametrize("head", ['format = "gfimu-array/1"\n', 'format = "gfimu-csv-map/1"\n',
                                  'format = "gfimu-calibration/1"\n'])
def test_a_syntax_error_names_the_file_and_line_in_every_input(tmp_path, head):
    path = tmp_path / "in.toml"
    text = head + UNCLOSED
    path.write_text(text)
    expected = rf"^{path}:3: not valid TOML: .*\(at line 3, column 1\)$"
    with pytest.raises(LogFormatError, match=expected):
        load_toml(text, path)
    if "array" in head:
        with pytest.raises(LogFormatError, match=expected):
            parse_array_toml(text, path)
    elif "map" in head:
        with pytest.raises(LogFormatError, match=expected):
            parse_map(text, str(path))
    else:
        with pytest.raises(CalibrationFileError, match=expected):
            read_calibration(path)


def test_too_deep_a_file_is_refused_before_it_is_read(tmp_path):
    text = "x = " + "[" * 100 + "]" * 100 + "\n"
    with pytest.raises(LogFormatError, match=r"^m\.toml: nested deeper than 64 levels"):
        load_toml(text, "m.toml")


def test_an_unknown_key_of_a_map_table_is_named_with_its_line_and_the_known_ones():
    text = ('format = "gfimu-csv-map/1"\n[csv]\ndelimeter = ","\n[time]\ncolumn = 0\nunit = "s"\n'
            '[[accelerometers]]\nname = "a"\nx = 1\n')
    with pytest.raises(LogFormatError, match=r"^map\.toml:3: csv\.delimeter: unknown key 'delimeter' \(known: "
                                             r"delimiter, comment, header_row, skip_rows, decimal, file\)$"):
        parse_map(text, "map.toml")
    with pytest.raises(LogFormatError, match=r"^map\.toml:4: time\.units: unknown key 'units' \(known: column, "
                                             r"unit\)$"):
        parse_map(text.replace("[csv]\ndelimeter = \",\"\n", "").replace('unit = "s"', 'units = "s"'), "map.toml")
