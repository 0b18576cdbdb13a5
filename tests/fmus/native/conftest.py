"""Fixtures of the native tests: the C importer, compiled once per session."""

import pytest

from native_harness import compile_importer


@pytest.fixture(scope="session")
def importer(tmp_path_factory):
    return compile_importer(tmp_path_factory.mktemp("importer"))
