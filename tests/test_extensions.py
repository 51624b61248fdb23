"""Modules of one's own named in $OGM_PPL_METHODS: one that ends the process on import is named, not obeyed."""

import pytest

from ogm_ppl import extensions
from ogm_ppl.cli import main
from ogm_ppl.methods import registry


@pytest.fixture
def plugin(tmp_path, monkeypatch):
    """A module ``exiting_plugin_xyz`` on ``sys.path`` that calls ``sys.exit`` on import; the registries forget
    what they loaded (and again afterwards)."""
    (tmp_path / "exiting_plugin_xyz.py").write_text('import sys\nsys.exit("licence server unreachable")\n')
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setattr(registry, "_discovered", False)
    monkeypatch.setattr(extensions, "_loaded", False)
    monkeypatch.setenv("OGM_PPL_METHODS", "exiting_plugin_xyz")
    yield "exiting_plugin_xyz"
    monkeypatch.delenv("OGM_PPL_METHODS")
    extensions._loaded = False


def test_a_plugin_that_calls_sys_exit_is_a_typed_error_naming_it_and_the_exit(plugin):
    """``sys.exit("...")`` at import raises :class:`MethodModuleError` (not ``SystemExit``) naming the variable,
    the module and the exit's argument; the next call tries again."""
    with pytest.raises(extensions.MethodModuleError) as e:
        extensions.load_extensions()
    msg = str(e.value)
    assert "$OGM_PPL_METHODS names the module 'exiting_plugin_xyz'" in msg
    assert "sys.exit('licence server unreachable')" in msg
    assert not extensions._loaded


def test_a_plugin_that_calls_sys_exit_is_one_error_line_on_the_command_line(plugin, capsys):
    """``ogm-ppl methods`` with such a plugin: exit status 2 and one line saying which plugin and what it did."""
    assert main(["methods"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("ogm-ppl: error: $OGM_PPL_METHODS names the module"), err
    assert "exiting_plugin_xyz" in err[0] and "called sys.exit('licence server unreachable') on import" in err[0]
