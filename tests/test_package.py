"""The package's top level: the version, every listed submodule, the public names."""

import importlib.metadata
from pathlib import Path

import rffqm_nlp as rq


def test_version_comes_from_the_installed_metadata():
    assert rq.__version__ == importlib.metadata.version("rffqm_nlp")


def test_every_module_of_the_package_is_listed_and_imports():
    modules = {p.stem for p in Path(rq.__file__).parent.glob("*.py")} - {"__init__"}
    # rq.fold and rq.collisions are the functions; their modules are marching and collisions
    assert modules - {"collisions"} == set(rq._SUBMODULES)
    for name in rq._SUBMODULES:
        assert getattr(rq, name).__name__ == f"rffqm_nlp.{name}"


def test_public_names_resolve():
    for name in rq.__all__:
        assert getattr(rq, name) is not None
    assert callable(rq.collisions) and rq.collisions.__module__ == "rffqm_nlp.collisions"
