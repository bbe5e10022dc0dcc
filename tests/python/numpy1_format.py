"""The reference our .npy/pickle writers match byte for byte is what Debian 12's numpy 1.24
writes (the ZJU-MoCap files and the reference implementation come from numpy 1.x). numpy 2
writes two things differently, though it still reads the 1.x files:
  * arrays and numpy scalars pickle through `numpy._core.multiarray` (1.x: `numpy.core.multiarray`);
  * np.save pickles object arrays at protocol 4 (1.x: protocol 3).
Importing this module makes pickle write the 1.x names under numpy 2 (the function objects are
the same: numpy 2 still resolves `numpy.core.multiarray._reconstruct` to them), and `save` is
np.save as numpy 1.x wrote it. Under numpy 1.x both are no-ops. Used by the fixture scripts and
the checks, so that the byte comparisons hold in the Debian 13 root (numpy 2.2) too.
"""
import pickle
import sys

import numpy as np

NUMPY_MAJOR = int(np.__version__.split('.')[0])

# Where pickle.dumps itself is the byte reference: Debian 12's CPython 3.11 with numpy 1.x.
# Elsewhere (Debian 13: CPython 3.13, numpy 2.2) CPython shares some objects differently in the
# memo (e.g. an array's b'b' typecode), so the checks compare with digests of the reference
# environment's bytes instead (tests/python/pickle_digests.txt).
REFERENCE_ENVIRONMENT = sys.version_info[:2] == (3, 11) and NUMPY_MAJOR == 1

if NUMPY_MAJOR >= 2:
    import numpy._core.multiarray as _multiarray

    for _name in ('_reconstruct', 'scalar'):
        getattr(_multiarray, _name).__module__ = 'numpy.core.multiarray'


def save(path_or_file, value):
    """np.save(path_or_file, value, allow_pickle=True), with numpy 1.x's bytes."""
    array = np.asanyarray(value)
    if NUMPY_MAJOR < 2 or array.dtype != object:
        np.save(path_or_file, array, allow_pickle=True)
        return
    if isinstance(path_or_file, (str, bytes)) or hasattr(path_or_file, '__fspath__'):
        with open(path_or_file, 'wb') as f:
            save(f, array)
        return
    np.lib.format.write_array_header_1_0(path_or_file, np.lib.format.header_data_from_array_1_0(array))
    pickle.dump(array, path_or_file, protocol=3)
