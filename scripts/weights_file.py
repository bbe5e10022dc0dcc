"""Reading a torch-saved weights file without running code from it (the export scripts share it).

torch.load unpickles: a file made to run code would run it. load_weights() reads with
weights_only=True, which accepts tensors and plain containers only, and turns every failure into
one line on stderr and exit status 2 (no traceback).
"""
import inspect
import sys

import torch


def fail(message):
    """One line on stderr, exit status 2 (a user error)."""
    print(f"{sys.argv[0].rsplit('/', 1)[-1]}: error: {message}", file=sys.stderr)
    sys.exit(2)


def load_weights(path, what):
    """The contents of the torch-saved file `path` (tensors in dicts and lists), `what` naming it
    in messages. Exits 2 when the file is missing, is not a torch file, or names anything else
    (a class or function: nothing of it is run)."""
    if "weights_only" not in inspect.signature(torch.load).parameters:
        fail(f"torch {torch.__version__} cannot read weights without unpickling code (torch.load has no "
             f"weights_only); {what} '{path}' was not read")
    try:
        return torch.load(path, map_location="cpu", weights_only=True)
    except FileNotFoundError:
        fail(f"{what} '{path}' does not exist")
    except IsADirectoryError:
        fail(f"{what} '{path}' is a folder, not a file")
    except Exception as e:  # noqa: BLE001: every reason is reported in one line
        text = str(e)
        marker, named = "WeightsUnpickler error:", "Unsupported class "
        detail = text.split(marker, 1)[1].strip().splitlines()[0] if marker in text else ""
        if detail.startswith(named):
            reason = f"it names {detail[len(named):]}, not only tensors (nothing of it was run)"
        else:
            why = detail or f"{type(e).__name__}: {(text.strip().splitlines() or [''])[0]}"
            reason = f"it is neither a torch zip archive nor a pickle of tensors ({why})"
        fail(f"{what} '{path}' is not a weights file: {reason}")
