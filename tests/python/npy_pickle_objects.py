"""Objects that both the Python fixture scripts and the C++ io tests build from the same
formulas (tests/io/*.cpp repeat them with torch), so that each side checks the other against
an independent computation.

Strings are written as literals, the way a script would build such dicts: the pickle writer
under test reproduces what CPython writes for them (equal literals are one object).
"""
import collections
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import numpy1_format  # noqa: E402,F401  (numpy 2 pickles with numpy 1.x's names from here on)

DTYPE_CODES = ['f2', 'f4', 'f8', 'i1', 'i2', 'i4', 'i8', 'u1', 'u2', 'u4', 'b1']
WRITABLE_CODES = ['f2', 'f4', 'f8', 'i1', 'i2', 'i4', 'i8', 'u1', 'b1']


def dtype_values(code, shape=(2, 3, 4)):
    """Element i (C order) of each test array, per dtype."""
    i = np.arange(int(np.prod(shape)), dtype=np.int64)
    kind = code[0]
    if kind == 'f':
        v = (i * 0.5 - 3).astype(code)
    elif code == 'i1':
        v = (i * 7 - 80).astype(code)
    elif kind == 'i':
        v = (i * 37 - 300).astype(code)
    elif code == 'u1':
        v = (i * 11).astype(code)
    elif code == 'u2':
        v = (i * 2000 + 7).astype(code)
    elif code == 'u4':
        v = (i * 100000000 + 5).astype(code)
    else:
        v = (i % 3 == 0)
    return v.reshape(shape)


def big_endian(a):
    return a.astype(a.dtype.newbyteorder('>'))


def annots(ncams=23, nframes=4):
    """ZJU-MoCap's annots.npy: cams K/R/T/D lists and per-frame image lists."""
    K, R, T, D = [], [], [], []
    for c in range(ncams):
        K.append(np.array([[1000.0 + c, 0.0, 512.0], [0.0, 1001.0 + c, 500.0], [0.0, 0.0, 1.0]]))
        R.append(np.arange(9, dtype=np.float64).reshape(3, 3) * 0.125 + c)
        T.append(np.array([[c * 10.5], [c * -2.25], [1000.0 + c]]))
        D.append(np.array([[0.5 ** (k + 1) * c] for k in range(5)]))
    ims = []
    for f in range(nframes):
        ims.append({'ims': ['Camera_B%d/%06d.jpg' % (c + 1, f) for c in range(ncams)]})
    return {'cams': {'K': K, 'R': R, 'T': T, 'D': D}, 'ims': ims}


def params():
    """ZJU-MoCap's params/<i>.npy."""
    return {
        'poses': (np.arange(72, dtype=np.float64) * 0.01).reshape(1, 72),
        'Rh': np.array([[0.1, 0.2, 0.3]]),
        'Th': np.array([[0.5, -0.25, 2.0]]),
        'shapes': (np.arange(10, dtype=np.float64) * 0.1 - 0.5).reshape(1, 10),
    }


def mixed_object():
    """Everything the reader handles in one dict (pickled at protocols 2-5 by the fixtures)."""
    shared = [1, 2]
    return {
        'int_small': 7, 'int_neg': -3, 'int_2b': 300, 'int_4b': 70000,
        'int_big': 2 ** 40, 'int_neg_big': -2 ** 40, 'int_max': 2 ** 63 - 1, 'int_min': -2 ** 63,
        'float': 2.5, 'inf': float('inf'),
        'str': 'héllo wörld', 'bytes': b'\x00\xffabc', 'none': None, 'true': True, 'false': False,
        'list': [1, 'a', 2.0], 'tuple': (1, 2, 3, 4), 'tuple1': (5,), 'empty_tuple': (),
        'nested': {'a': [{'b': (1,)}]},
        'set': {1, 2, 3}, 'frozenset': frozenset({4}),
        'shared': [shared, shared],
        'f4': np.arange(6, dtype=np.float32).reshape(2, 3),
        'big_endian': np.arange(6, dtype='>i4'),
        'fortran': np.asfortranarray(np.arange(6.0).reshape(2, 3)),
        'bools': np.array([True, False, True]),
        'empty': np.zeros((0, 3)),
        'scalar_f8': np.float64(1.5), 'scalar_i8': np.int64(-5),
        'dtype': np.dtype('>f4'),
        'objects': np.array([{'a': 1}, 'x', None], dtype=object),
        'ordered': collections.OrderedDict([('z', 1), ('a', 2)]),
        'dtypes': {code: dtype_values(code) for code in DTYPE_CODES},
        'dtypes_be': {code: big_endian(dtype_values(code)) for code in DTYPE_CODES},
        'dtypes_F': {code: np.asfortranarray(big_endian(dtype_values(code))) for code in DTYPE_CODES},
        'many': list(range(2500)),
        'long_str': 'x' * 70000,
        'big': np.arange(20000, dtype=np.float64) * 0.25,
    }


def writer_object():
    """What the C++ pickle writer must write byte for byte as CPython does."""
    return {
        'none': None, 'true': True, 'false': False,
        'ints': [0, 255, 256, 65535, 65536, -1, -2 ** 31, 2 ** 31 - 1, 2 ** 31, -2 ** 31 - 1,
                 2 ** 62, -2 ** 63, 2 ** 63 - 1, 1 << 40, -(1 << 40)],
        'floats': [0.0, -0.0, 1.5, 1e300, float('inf'), float('-inf'), float('nan')],
        'str': 'héllo', 'empty': '', 'chars': ['a', '<', '/', 'Z'],
        'repeat': ['same text', 'same text', 'Camera_B1/000000.jpg'],
        'bytes': b'\x00\x01binary', 'b1': b'b', 'b0': b'',
        'tuple0': (), 'tuple2': (1, 'x'), 'tuple5': (1, 2, 3, 4, 5),
        'nested': {'inner': [[], {}, [1]]},
        'arrays': [np.zeros((2, 3)), np.arange(5, dtype=np.int32), np.array(True),
                   np.array([1, 2], dtype=np.uint8), np.array([[1.5]], dtype=np.float32),
                   np.arange(24, dtype=np.int64).reshape(2, 3, 4), np.zeros((0, 3)),
                   np.zeros((1, 1, 2, 1), dtype=np.float32), np.array([1], dtype=np.uint8),
                   np.arange(3, dtype=np.int8), np.arange(3, dtype=np.int16),
                   np.arange(3, dtype=np.float16)],
        'numpy': 1, 'latin1': 2,
    }


def writer_big_object():
    """Large enough for several protocol-4 frames and for payloads outside frames."""
    return {
        'big': np.arange(20000, dtype=np.float64) * 0.25,
        'many': [np.full(3, i, dtype=np.float32) for i in range(3000)],
        'long': 'x' * 70000,
        'mid': 'y' * 65535,
        'ints': list(range(3000)),
    }


def writer_batches_object():
    """Lists and dicts at and around pickle's batch size of 1000. (Keys made at runtime are
    distinct objects in Python even when equal; the writer shares equal strings, so the two
    dicts use different keys.)"""
    return {
        'l1000': list(range(1000)), 'l2000': list(range(2000)), 'l1001': list(range(1001)),
        'd1000': {'k%d' % i: i for i in range(1000)},
        'd2001': {'j%d' % i: i for i in range(2001)},
    }


def equal(a, b, path='obj'):
    """Deep equality with numpy arrays (dtype, shape, values; NaN == NaN); returns an error
    message or None."""
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        if not (isinstance(a, np.ndarray) and isinstance(b, np.ndarray)):
            return '%s: %s vs %s' % (path, type(a).__name__, type(b).__name__)
        if a.dtype != b.dtype or a.shape != b.shape:
            return '%s: %s%s vs %s%s' % (path, a.dtype, a.shape, b.dtype, b.shape)
        if a.dtype == object:
            for k, (x, y) in enumerate(zip(a.ravel(), b.ravel())):
                msg = equal(x, y, '%s[%d]' % (path, k))
                if msg:
                    return msg
            return None
        ok = np.array_equal(a, b, equal_nan=a.dtype.kind == 'f')
        return None if ok else '%s: values differ' % path
    if type(a) is not type(b):
        return '%s: %s vs %s' % (path, type(a).__name__, type(b).__name__)
    if isinstance(a, dict):
        if list(a.keys()) != list(b.keys()):
            return '%s: keys %s vs %s' % (path, list(a.keys())[:8], list(b.keys())[:8])
        for k in a:
            msg = equal(a[k], b[k], '%s[%r]' % (path, k))
            if msg:
                return msg
        return None
    if isinstance(a, (list, tuple)):
        if len(a) != len(b):
            return '%s: length %d vs %d' % (path, len(a), len(b))
        for k, (x, y) in enumerate(zip(a, b)):
            msg = equal(x, y, '%s[%d]' % (path, k))
            if msg:
                return msg
        return None
    if isinstance(a, float) and a != a and b != b:
        return None
    return None if a == b else '%s: %r vs %r' % (path, a, b)
