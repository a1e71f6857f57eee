import numpy as np
import pytest

from helpers import scene_text


@pytest.fixture
def rng():
    return np.random.default_rng(20261122)


@pytest.fixture
def scene_file(tmp_path):
    """Writes a shared test scene (tests/data/scenes/<name>.toml) into tmp_path, changed by
    ``edits`` — (old, new) pairs, each of which must occur in the text — and returns its path."""
    def write(name, *edits, to=None):
        text = scene_text(name)
        for old, new in edits:
            assert old in text, old
            text = text.replace(old, new)
        path = tmp_path / (to or f"{name}.toml")
        path.write_text(text)
        return path
    return write
