"""The installed version of rffqm_nlp (FOLD files and the command line name it)."""

import importlib.metadata

__version__ = importlib.metadata.version("rffqm_nlp")
