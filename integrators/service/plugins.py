"""User code named on the command line or in a scene: ``module:function`` or ``path/to/file.py:function``.

One loader for every place a function is accepted (step maps for ``poincare audit``, loop and
surface shapes in scenes).  A module is imported with the current directory first on the path,
as ``python -c`` would (the ``poincare`` console script alone would not see it); a relative
``file.py`` is looked up in ``base`` (a scene file's directory) and then in the current
directory.  Every failure is one ValueError naming the spec.
"""
from __future__ import annotations

import importlib
import importlib.util
import os
import sys
from pathlib import Path
from typing import Callable


def is_spec(text: str) -> bool:
    """True when ``text`` names user code (module:function or file.py:function)."""
    return isinstance(text, str) and ":" in text and not text.endswith(":")


def load_callable(spec: str, what: str = "function", base: str | Path | None = None) -> Callable:
    """The callable named by ``spec``; ``what`` names it in errors ("step map", "loop.shape")."""
    if not is_spec(spec):
        raise ValueError(f"{what} '{spec}' must be given as module:function or file.py:function")
    mod_name, func_name = spec.rsplit(":", 1)
    try:
        if mod_name.endswith(".py"):
            path = Path(mod_name)
            candidates = [path] if path.is_absolute() else \
                [*([Path(base) / path] if base is not None else []), Path.cwd() / path]
            found = next((c for c in candidates if c.is_file()), None)
            if found is None:
                raise ValueError(f"{what}: file '{mod_name}' not found"
                                 + (f" (looked in {', '.join(str(c.parent) for c in candidates)})" if candidates else ""))
            key = f"_poincare_user_{abs(hash(str(found.resolve())))}"
            module = sys.modules.get(key)
            if module is None:
                spec_ = importlib.util.spec_from_file_location(key, found)
                module = importlib.util.module_from_spec(spec_)
                spec_.loader.exec_module(module)
                sys.modules[key] = module
        else:
            added = os.getcwd() not in sys.path and "" not in sys.path
            if added:
                sys.path.insert(0, os.getcwd())
            try:
                module = importlib.import_module(mod_name)
            finally:
                if added:
                    sys.path.remove(os.getcwd())
    except ValueError:
        raise
    except Exception as exc:   # the user's module failed to import: say why in one line
        raise ValueError(f"{what}: cannot import '{mod_name}': {type(exc).__name__}: {exc}") from None
    fn = getattr(module, func_name, None)
    if not callable(fn):
        raise ValueError(f"{what}: '{mod_name}' has no function '{func_name}'")
    return fn
