"""User code named on the command line or in a scene: ``module:function`` or ``path/to/file.py:function``.

One loader for every place a function is accepted (step maps for ``poincare audit``, loop and
surface shapes and systems in scenes).  A scene that names code runs it, like a script, so the
code must be the user's own: a relative ``file.py`` or a ``module`` (as ``module.py`` or a
package folder) is looked up in ``base`` (a scene file's directory) and then in the current
directory, and nowhere else; installed modules are refused.  Every failure is one ValueError
naming the spec.
"""
from __future__ import annotations

import importlib.util
import sys
from pathlib import Path
from typing import Callable


def is_spec(text: str) -> bool:
    """True when ``text`` names user code (module:function or file.py:function)."""
    return isinstance(text, str) and ":" in text and not text.endswith(":")


LOADED: dict = {}        # {(key, spec): '/path/to/file.py:function'}: the user code this process ran


def _module_file(mod_name, places):
    """The file of module ``a.b.c`` under one of ``places``: a/b/c.py or a/b/c/__init__.py, or None."""
    rel = Path(*mod_name.split("."))
    for place in places:
        for cand in (place / rel.with_suffix(".py"), place / rel / "__init__.py"):
            if cand.is_file():
                return cand
    return None


def _inside(path, places) -> bool:
    """Whether ``path`` (resolved: through symlinks) lies in one of ``places`` or below."""
    path = path.resolve()
    return any(path.is_relative_to(place.resolve()) for place in places)


def load_callable(spec: str, what: str = "function", base: str | Path | None = None,
                  confined: bool = True) -> Callable:
    """The callable named by ``spec``; ``what`` names it in errors ("step map", "loop.shape").

    User code runs, like a script, only from where the user put it: ``file.py`` next to the scene
    (``base``) or in the current directory, or below either, ``module`` (dotted: a package's
    module) as a ``.py`` file or package found there.  A file elsewhere (``../maps.py``, an absolute
    path, a symlink out) and an installed module (``builtins:print``, ``os:system``) are refused: a
    scene names code of its own, not the machine's.  ``confined`` False (``poincare audit``'s
    command line, which the user types) also takes a file anywhere.  What was loaded is recorded in
    :data:`LOADED` for the run's summary.  The callable comes back :func:`~.stop.guarded`: a signal
    interrupts it where it is, and its ``sys.exit`` is a failure of the code, not of the run."""
    if not is_spec(spec):
        raise ValueError(f"{what} '{spec}' must be given as module:function or file.py:function")
    mod_name, func_name = spec.rsplit(":", 1)
    places = [*([Path(base)] if base is not None else []), Path.cwd()]
    try:
        if mod_name.endswith(".py"):
            path = Path(mod_name)
            candidates = [path] if path.is_absolute() else [place / path for place in places]
            found = next((c for c in candidates if c.is_file()), None)
            if found is None:
                raise ValueError(f"{what}: file '{mod_name}' not found"
                                 + (f" (looked in {', '.join(str(c.parent) for c in candidates)})" if candidates else ""))
            if confined and not _inside(found, places):
                raise ValueError(f"{what}: '{mod_name}' is outside "
                                 f"{' and '.join(repr(str(p)) for p in dict.fromkeys(places))}; a scene runs "
                                 "only code of its own from its folder or the current directory (copy the file there)")
        else:
            if not all(part.isidentifier() for part in mod_name.split(".")):
                raise ValueError(f"{what}: '{mod_name}' is not a module name")
            found = _module_file(mod_name, places)
            if found is None:
                raise ValueError(f"{what}: module '{mod_name}' is not a .py file or package in "
                                 f"{' or '.join(str(p) for p in dict.fromkeys(places))}; a scene runs only code of "
                                 "its own from there, never an installed module")
            if confined and not _inside(found, places):
                raise ValueError(f"{what}: module '{mod_name}' leads outside "
                                 f"{' and '.join(repr(str(p)) for p in dict.fromkeys(places))} (a symlink?); a "
                                 "scene runs only code of its own from its folder or the current directory")
        found = found.resolve()
        key = f"_poincare_user_{abs(hash(str(found)))}"
        module = sys.modules.get(key)
        from .stop import guarded
        if module is None:
            # as a script: the file's folder on the import path, so that it can import a module beside it
            # (at import or inside its functions); only the folder the code was taken from
            folder = str(found.parent if found.name != "__init__.py" else found.parent.parent)
            if folder not in sys.path:
                sys.path.append(folder)
            spec_ = importlib.util.spec_from_file_location(key, found)
            module = importlib.util.module_from_spec(spec_)
            sys.modules[key] = module
            try:
                guarded(spec_.loader.exec_module, f"{what} '{spec}'")(module)
            except BaseException:
                del sys.modules[key]
                raise
    except ValueError:
        raise
    except Exception as exc:   # the user's module failed to import: say why in one line
        raise ValueError(f"{what}: cannot import '{mod_name}': {type(exc).__name__}: {exc}") from None
    fn = getattr(module, func_name, None)
    if not callable(fn):
        raise ValueError(f"{what}: '{mod_name}' has no function '{func_name}'")
    LOADED[(what, spec)] = f"{found}:{func_name}"
    from .stop import guarded
    return guarded(fn, f"{what} '{spec}'")
