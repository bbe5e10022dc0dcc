"""Writes the .npy/.npz/pickle fixtures of tests/io with numpy/scipy/pickle themselves.

Usage: make_io_fixtures.py <out_dir>

Besides files numpy writes directly, it assembles a Python-2-style protocol-2 SMPL pickle
(BINSTRING data, copy_reg/__builtin__ names) opcode by opcode, and a few hostile pickles.
"""
import collections
import copyreg
import io
import os
import pickle
import struct
import sys
import types
import warnings

import numpy as np
import scipy.sparse

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import npy_pickle_objects as objs  # noqa: E402
import numpy1_format  # noqa: E402


# A stand-in for chumpy (not installed): pickles as chumpy.ch.Ch through
# copyreg._reconstructor with its __dict__ as state, like chumpy objects in SMPL files.
class Ch(object):
    def __init__(self, x):
        self.x = x
        self._dirty_vars = {'x'}
        self._depends_on_deps = {}
        self.label = None

    def __reduce__(self):
        return (copyreg._reconstructor, (Ch, object, None), self.__dict__)


Ch.__module__ = 'chumpy.ch'
Ch.__qualname__ = 'Ch'
_chumpy = types.ModuleType('chumpy')
_chumpy_ch = types.ModuleType('chumpy.ch')
_chumpy_ch.Ch = Ch
_chumpy.ch = _chumpy_ch
sys.modules['chumpy'] = _chumpy
sys.modules['chumpy.ch'] = _chumpy_ch


class Evil(object):
    def __init__(self, fn, arg):
        self.fn, self.arg = fn, arg

    def __reduce__(self):
        return (self.fn, (self.arg,))


def smpl_arrays(posedirs_depth, nverts=6890):
    rng = np.random.default_rng(0)
    dense_j = np.where(rng.random((24, nverts)) < 0.002, rng.random((24, nverts)), 0.0)
    return {
        'J_regressor': dense_j,
        'weights': rng.random((nverts, 24)),
        'v_template': rng.random((nverts, 3)),
        'shapedirs': rng.random((nverts, 3, 10)),
        # A formula (repeated by the C++ tests) instead of a stored copy of 34 MB.
        'posedirs': ((np.arange(nverts * 3 * posedirs_depth) % 1000) * 0.001).reshape(nverts, 3, posedirs_depth),
        'f': rng.integers(0, nverts, (2 * nverts - 4, 3)).astype(np.uint32),
        'kintree_table': np.stack([np.arange(24) - 1, np.arange(24)]).astype(np.int64),
        'J': rng.random((24, 3)),
    }


class Py2Pickle(object):
    """Assembles a protocol-2 pickle the way Python 2's cPickle wrote SMPL files: str as
    SHORT_BINSTRING/BINSTRING, Python 2 module names, globals memoized and fetched again."""

    def __init__(self):
        self.out = bytearray(b'\x80\x02')
        self.n = 0
        self.globals = {}

    def put(self):
        self.out += (b'q' + bytes([self.n])) if self.n < 256 else (b'r' + struct.pack('<I', self.n))
        self.n += 1
        return self.n - 1

    def get(self, index):
        self.out += (b'h' + bytes([index])) if index < 256 else (b'j' + struct.pack('<I', index))

    def string(self, s):
        if isinstance(s, str):
            s = s.encode('latin1')
        if len(s) < 256:
            self.out += b'U' + bytes([len(s)]) + s
        else:
            self.out += b'T' + struct.pack('<i', len(s)) + s
        self.put()

    def int(self, v):
        if 0 <= v < 256:
            self.out += b'K' + bytes([v])
        elif 0 <= v < 65536:
            self.out += b'M' + struct.pack('<H', v)
        else:
            self.out += b'J' + struct.pack('<i', v)

    def glob(self, module, name):
        key = (module, name)
        if key in self.globals:
            self.get(self.globals[key])
        else:
            self.out += b'c' + module.encode() + b'\n' + name.encode() + b'\n'
            self.globals[key] = self.put()

    def tuple(self, items, emit):
        if len(items) <= 3 and items:
            for x in items:
                emit(x)
            self.out += bytes([0x84 + len(items)])
        else:
            self.out += b'('
            for x in items:
                emit(x)
            self.out += b't'
        self.put()

    def dtype(self, dt):
        self.glob('numpy', 'dtype')
        self.string('%s%d' % (dt.kind, dt.itemsize))
        self.int(0)
        self.int(1)
        self.out += b'\x87'
        self.put()
        self.out += b'R'
        self.put()
        self.out += b'('
        self.int(3)
        self.string('|' if dt.itemsize == 1 else ('>' if dt.byteorder == '>' else '<'))
        self.out += b'NNN'
        self.out += b'J' + struct.pack('<i', -1) + b'J' + struct.pack('<i', -1)
        self.int(0)
        self.out += b't'
        self.put()
        self.out += b'b'

    def array(self, a):
        self.glob('numpy.core.multiarray', '_reconstruct')
        self.glob('numpy', 'ndarray')
        self.tuple([0], self.int)
        self.string(b'b')
        self.out += b'\x87'
        self.put()
        self.out += b'R'
        self.put()
        self.out += b'('
        self.int(1)
        self.tuple(list(a.shape), self.int)
        self.dtype(a.dtype)
        fortran = a.flags.f_contiguous and not a.flags.c_contiguous
        self.out += b'\x88' if fortran else b'\x89'
        self.string(a.tobytes(order='F' if fortran else 'C'))
        self.out += b't'
        self.put()
        self.out += b'b'

    def value(self, v):
        if isinstance(v, np.ndarray):
            self.array(v)
        elif isinstance(v, (str, bytes)):
            self.string(v)
        elif isinstance(v, bool):
            self.out += b'\x88' if v else b'\x89'
        elif isinstance(v, int):
            self.int(v)
        elif v is None:
            self.out += b'N'
        elif isinstance(v, tuple):
            self.tuple(list(v), self.value)
        elif isinstance(v, set):
            self.glob('__builtin__', 'set')
            self.out += b']'
            self.put()
            self.out += b'('
            for x in sorted(v):
                self.value(x)
            self.out += b'e'
            self.out += b'\x85'
            self.put()
            self.out += b'R'
            self.put()
        elif isinstance(v, dict):
            self.dict(v)
        else:
            raise TypeError(type(v))

    def dict(self, d):
        self.out += b'}'
        self.put()
        self.out += b'('
        for k, v in d.items():
            self.string(k)
            self.value(v)
        self.out += b'u'

    def reconstructed(self, module, cls, state):
        self.glob('copy_reg', '_reconstructor')
        self.out += b'('
        self.glob(module, cls)
        self.glob('__builtin__', 'object')
        self.out += b'N'
        self.out += b't'
        self.put()
        self.out += b'R'
        self.put()
        self.dict(state)
        self.out += b'b'

    def finish(self):
        return bytes(self.out + b'.')


def py2_smpl(arrays):
    """SMPL's official layout: a dict with a csc J_regressor and a chumpy shapedirs."""
    p = Py2Pickle()
    csc = scipy.sparse.csc_matrix(arrays['J_regressor'])
    p.out += b'}'
    p.put()
    p.out += b'('
    for key in ['J_regressor', 'weights', 'v_template', 'shapedirs', 'posedirs', 'f', 'kintree_table', 'J',
                'bs_style', 'bs_type']:
        p.string(key)
        if key == 'J_regressor':
            p.reconstructed('scipy.sparse.csc', 'csc_matrix', {
                'data': csc.data, 'indices': csc.indices, 'indptr': csc.indptr,
                '_shape': csc.shape, 'format': 'csc', 'maxprint': 50})
        elif key == 'shapedirs':
            p.reconstructed('chumpy.ch', 'Ch', {
                'x': arrays['shapedirs'], '_dirty_vars': {'x'}, '_depends_on_deps': {}, 'label': None})
        elif key == 'bs_style':
            p.string('lbs')
        elif key == 'bs_type':
            p.string('lrotmin')
        else:
            p.array(arrays[key])
    p.string('scale')  # data short enough for SHORT_BINSTRING
    p.array(np.array([1.5, 2.5]))
    p.out += b'u'
    return p.finish()


def hostile(p_out):
    """Pickles that must be refused."""
    p = Py2Pickle()
    p.glob('numpy.core.multiarray', '_reconstruct')
    p.glob('numpy', 'ndarray')
    p.tuple([0], p.int)
    p.string(b'b')
    p.out += b'\x87R('
    p.int(1)
    p.out += b'\x8a\x06' + (2 ** 41).to_bytes(6, 'little') + b'\x85'
    p.dtype(np.dtype('f8'))
    p.out += b'\x89'
    p.string(b'\0' * 8)
    p.out += b'tb'
    p_out['absurd_shape.pkl'] = p.finish()

    p = Py2Pickle()
    p.array(np.zeros(3))
    data = bytearray(p.finish())
    # Claim 1000 elements for the 24 bytes of data: BININT1 3 -> BININT2 1000.
    i = data.index(b'K\x03\x85')
    p_out['shape_mismatch.pkl'] = bytes(data[:i] + b'M' + struct.pack('<H', 1000) + data[i + 2:])

    p = Py2Pickle()
    p.reconstructed('scipy.sparse.csc', 'csc_matrix', {
        'data': np.ones(1), 'indices': np.zeros(1, dtype=np.int32),
        'indptr': np.array([0, 1], dtype=np.int32), '_shape': (1000000, 1000000)})
    p_out['absurd_sparse.pkl'] = p.finish()

    for proto in (2, 3, 4, 5):
        p_out['os_system_p%d.pkl' % proto] = pickle.dumps(Evil(os.system, 'touch PWNED'), protocol=proto)
    p_out['eval_p2.pkl'] = pickle.dumps(Evil(eval, '1+1'), protocol=2)
    p_out['oob_p5.pkl'] = pickle.dumps(np.arange(3.0), protocol=5, buffer_callback=lambda b: False)


def main():
    out = sys.argv[1]
    os.makedirs(out, exist_ok=True)

    def path(name):
        return os.path.join(out, name)

    # .npy of every dtype, both byte orders, C and Fortran order.
    for code in objs.DTYPE_CODES:
        base = objs.dtype_values(code)
        orders = ['le', 'be'] if base.dtype.itemsize > 1 else ['le']
        for endian in orders:
            a = base.astype(base.dtype.newbyteorder('>' if endian == 'be' else '<'))
            np.save(path('dtype_%s_%s_C.npy' % (code, endian)), a)
            np.save(path('dtype_%s_%s_F.npy' % (code, endian)), np.asfortranarray(a))
            assert np.load(path('dtype_%s_%s_F.npy' % (code, endian))).flags.f_contiguous
    for version in [(1, 0), (2, 0), (3, 0)]:
        with open(path('version_%d.npy' % version[0]), 'wb') as f:
            np.lib.format.write_array(f, objs.dtype_values('f8'), version=version)
    np.save(path('scalar.npy'), np.array(2.5))
    np.save(path('empty.npy'), np.zeros((0, 3), dtype=np.float32))
    with open(path('py2_header.npy'), 'wb') as f:  # Python 2 numpy wrote longs as 2L
        header = "{'descr': '<f8', 'fortran_order': False, 'shape': (2L, 3L), }"
        header += ' ' * (64 - (10 + len(header) + 1) % 64) + '\n'
        f.write(b'\x93NUMPY\x01\x00' + struct.pack('<H', len(header)) + header.encode())
        f.write(np.arange(6, dtype='<f8').tobytes())

    # Object .npy as ZJU-MoCap ships them.
    numpy1_format.save(path('annots.npy'), objs.annots())
    numpy1_format.save(path('params.npy'), objs.params())
    numpy1_format.save(path('annots_small.npy'), objs.annots(ncams=2, nframes=1))
    numpy1_format.save(path('object_1d.npy'), np.array([1, 'a', None], dtype=object))

    # .npz stored and deflated.
    np.savez(path('arrays.npz'), a=objs.dtype_values('f8'), b=objs.dtype_values('i4'), c=objs.dtype_values('b1'))
    np.savez_compressed(path('arrays_compressed.npz'), a=objs.dtype_values('f8'),
                        big=np.arange(100000, dtype=np.int64) % 7)

    # Pickles at every protocol.
    for proto in (2, 3, 4, 5):
        with open(path('mixed_p%d.pkl' % proto), 'wb') as f:
            pickle.dump(objs.mixed_object(), f, protocol=proto)
        seed = {k: v for k, v in objs.mixed_object().items() if k not in ('many', 'long_str', 'big')}
        with open(path('seed_p%d.pkl' % proto), 'wb') as f:
            pickle.dump(seed, f, protocol=proto)
    small = {'params': objs.params(), 'list': [1, 'a', (2.5, None)], 'set': {1}, 'f4': np.arange(3, dtype=np.float32)}
    with open(path('small_p3.pkl'), 'wb') as f:
        pickle.dump(small, f, protocol=3)
    with open(path('small_p4.pkl'), 'wb') as f:
        pickle.dump(small, f, protocol=4)

    # SMPL-like model files: Python 3 at protocol 2 (NEWOBJ scipy, _codecs array bytes) and
    # the hand-assembled Python 2 one (BINSTRING, copy_reg._reconstructor), full posedirs.
    full = smpl_arrays(207)
    small_smpl = smpl_arrays(9)
    py3 = {k: v for k, v in small_smpl.items()}
    py3['J_regressor'] = scipy.sparse.csc_matrix(small_smpl['J_regressor'])
    py3['J_regressor_csr'] = scipy.sparse.csr_matrix(small_smpl['J_regressor'])
    py3['shapedirs'] = Ch(small_smpl['shapedirs'])
    py3['bs_style'] = 'lbs'
    py3['bs_type'] = 'lrotmin'
    with open(path('smpl_py3_p2.pkl'), 'wb') as f:
        pickle.dump(py3, f, protocol=2)
    np.savez(path('smpl_py3_expected.npz'), **{k: v.astype(np.int64) if v.dtype == np.uint32 else v
                                               for k, v in small_smpl.items()})
    data = py2_smpl(full)
    with open(path('smpl_py2.pkl'), 'wb') as f:
        f.write(data)
    # The assembled file must be what Python itself reads as the same model.
    with warnings.catch_warnings():
        warnings.simplefilter('ignore', DeprecationWarning)  # scipy.sparse.csc is the Python 2 name
        loaded = pickle.loads(data, encoding='latin1')
    assert (loaded['J_regressor'].toarray() == full['J_regressor']).all()
    assert (loaded['shapedirs'].x == full['shapedirs']).all() and loaded['shapedirs']._dirty_vars == {'x'}
    np.savez(path('smpl_py2_expected.npz'), **{k: v.astype(np.int64) if v.dtype == np.uint32 else v
                                               for k, v in full.items() if k != 'posedirs'})
    # Small SMPL-like files as fuzzing seeds.
    tiny = smpl_arrays(2, nverts=12)
    tiny['J_regressor'][0, 3] = 0.5
    with open(path('seed_smpl_py2.pkl'), 'wb') as f:
        f.write(py2_smpl(tiny))
    tiny_py3 = dict(tiny, J_regressor=scipy.sparse.csc_matrix(tiny['J_regressor']),
                    J_regressor_csr=scipy.sparse.csr_matrix(tiny['J_regressor']), shapedirs=Ch(tiny['shapedirs']))
    with open(path('seed_smpl_py3_p2.pkl'), 'wb') as f:
        pickle.dump(tiny_py3, f, protocol=2)
    with open(path('posedirs_p4.pkl'), 'wb') as f:
        pickle.dump({'posedirs': full['posedirs']}, f, protocol=4)

    hostile_files = {}
    hostile(hostile_files)
    for name, data in hostile_files.items():
        with open(path(name), 'wb') as f:
            f.write(data)

    with open(path('DONE'), 'w') as f:
        f.write('ok\n')


if __name__ == '__main__':
    main()
