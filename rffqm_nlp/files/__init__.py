"""Files on disk: TOML and JSON input, atomic writes, JSON without NaN, and whole-folder
replacement.

Every file is written atomically (a temporary file in the target folder, then
:func:`os.replace`). A command that writes a folder of files writes them into a staging
folder next to it and replaces the output folder whole (:func:`replace_folder`): a kill at
any moment leaves either the complete old folder or the complete new one, and the next run
into the same place cleans up what the killed one left.

Validation of the tables read from TOML (and of the same values given through the API) has
its one home here: a :class:`Key` says what a key allows, :func:`check_table` checks a table
against a dict of Keys, and every refusal is one :class:`InputError` line naming the key
(``[design] panels``) and what it allows, never quoting a string longer than a short name.

Reading TOML and JSON, bounded, and :func:`named_path` (:mod:`.reading`); atomic single
files and JSON (:mod:`.writing`); output folders replaced whole (:mod:`.folders`); :class:`Key`
and :func:`check_value` (:mod:`.validation`).
"""

from __future__ import annotations

from .folders import check_out_dir, recover_folder, replace_folder
from .reading import (MAX_JSON_BYTES, MAX_JSON_DIGITS, MAX_TOML_BYTES, named_path, read_json,
                      read_toml)
from .validation import (Key, check_table, check_value, describe_value, key_name, shown_name,
                         unknown_key)
from .writing import DIR_MODE, FILE_MODE, atomic_path, jsonable, write_json, write_text

__all__ = ["DIR_MODE", "FILE_MODE", "MAX_JSON_BYTES", "MAX_JSON_DIGITS", "MAX_TOML_BYTES",
           "Key", "atomic_path", "check_out_dir", "check_table", "check_value",
           "describe_value", "jsonable", "key_name", "named_path", "read_json", "read_toml",
           "recover_folder", "replace_folder", "shown_name", "unknown_key", "write_json",
           "write_text"]
