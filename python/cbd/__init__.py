"""cbd — Calibration by Diffeomorphisms for robot arms, from Python: numpy in, numpy out.

The same pipeline as the ``cbd`` command (a fit from Python and ``cbd fit`` on the same data give
the same blob bytes), and the runtime a controller runs for evaluation and compensation::

    import numpy as np, cbd
    model_file = cbd.ModelFile.load("examples/ur5/ur5.toml")
    data = np.loadtxt("examples/ur5/train.csv", delimiter=",", skiprows=1)
    model = cbd.fit(model_file, data[:, :6], data[:, 6:], dh_first=True)
    positions = model.evaluate(data[:, :6])                   # degrees in, mm out: the file's columns

Every array in and out is in the model file's column units, as ``cbd fit``'s CSV holds them (radians
only where the model file says so); a blob loaded without a model file is in its own units (radians,
the model's length unit). ``Model.units`` says which.

Progress and warnings go to the ``logging`` logger ``"cbd"``; failures raise :class:`CbdError`
(a ``ValueError``) with the command's message.
"""

import logging as _logging

from ._cbd import CbdError, Model, ModelFile, __version__, check, compare, diagnose, fit, simulate

_logging.getLogger("cbd").addHandler(_logging.NullHandler())


class CbdMemoryError(CbdError, MemoryError):
    """An array refused before it is copied: this process's memory could not hold it, read and
    answered (a broadcast view of 10^9 rows, say). Both a :class:`CbdError` (a ``ValueError``) and a
    ``MemoryError``; the message names the argument and its shape."""


__all__ = ["CbdError", "CbdMemoryError", "Model", "ModelFile", "__version__", "check", "compare", "diagnose", "fit", "simulate"]
