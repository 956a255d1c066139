"""The one function the client sends to Dask workers: call a ``drt.farm.tasks`` function by name.

Sent *by value* (its code, not a module reference): inside Blender the bundled core is a
sub-package of the extension (``bl_ext.user_default.drt.drt``), a name no worker can import,
while every worker has ``drt`` installed. So nothing DRT-specific is pickled by reference:
the scene travels as a ``Scene`` (CLI) or as the exporter's plain ``(header, arrays)``
(Blender), results come back as dicts of numpy arrays, and errors as ``RuntimeError``.
"""


def call(name, *args):
    """Call ``drt.farm.tasks.<name>`` ("render_task", "fingerprint") on the worker with ``args``.

    The import names the worker's installed ``drt`` (this code runs only on workers).
    Exceptions come back as ``RuntimeError("ClassName: message")``: a DRT exception class
    could not be unpickled by a client that imports the core under another name.
    """
    import drt.farm.tasks

    fn = getattr(drt.farm.tasks, name)
    try:
        return fn(*args)
    except Exception as e:  # noqa: BLE001 -- re-raised as a plain, portable exception
        raise RuntimeError(f"{e.__class__.__name__}: {e}") from None


# Dask pickles functions of ``__main__`` with cloudpickle, by value (distributed.protocol.pickle)
call.__module__ = "__main__"
