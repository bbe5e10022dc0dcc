"""Checks with numpy/pickle what the C++ io code wrote (tests/io), and writes numpy's own
copies back for the C++ side to read (the Python -> C++ half of the round trips).

Usage: check_io_written.py <mode> <dir>
  npy      npy_<code>.npy (and scalar/empty/1d/transposed): values, and bytes == np.save
  objects  annots.npy, params.npy: values, and bytes == np.save(dict); writes py_*.npy
  pickle   writer_p{2,3,4}.pkl, big_p{2,3,4}.pkl, batches_p{2,3,4}.pkl: bytes == pickle.dumps
           (CPython 3.11 + numpy 1.x), elsewhere SHA-256 == tests/python/pickle_digests.txt
  digests  writes tests/python/pickle_digests.txt (run in the reference environment only)
  sets     set_p{2,3,4}.pkl: pickle.loads equals {'s': {1, 'a', (2, 3)}, 'e': set()}
  npz      arrays.npz: np.load values; writes py_arrays.npz (np.savez_compressed)
Exit status 0 when everything matches; otherwise the mismatches are printed.
"""
import hashlib
import io
import os
import pickle
import pickletools
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import npy_pickle_objects as objs  # noqa: E402
import numpy1_format  # noqa: E402

failures = []


def fail(msg):
    failures.append(msg)
    print('MISMATCH: ' + msg)


def read(path):
    with open(path, 'rb') as f:
        return f.read()


def compare_bytes(name, got, want, pickled=False):
    if got == want:
        return
    at = next((i for i, (a, b) in enumerate(zip(got, want)) if a != b), min(len(got), len(want)))
    fail('%s: %d bytes vs numpy/pickle %d bytes, first difference at byte %d' % (name, len(got), len(want), at))
    if pickled:
        for label, data in (('written', got), ('expected', want)):
            print('--- %s, opcodes near byte %d:' % (label, at))
            for op, arg, pos in pickletools.genops(data):
                if at - 40 <= pos <= at + 40:
                    text = repr(arg)
                    print('  %6d %s %s' % (pos, op.name, text[:60]))


def npy_bytes(array):
    out = io.BytesIO()
    numpy1_format.save(out, array)
    return out.getvalue()


def check_npy(d):
    expected = {'npy_%s' % code: objs.dtype_values(code) for code in objs.WRITABLE_CODES}
    expected['scalar'] = np.array(2.5)
    expected['empty'] = np.zeros((0, 3), dtype=np.float32)
    expected['vector'] = np.arange(5, dtype=np.int64)
    expected['transposed'] = np.ascontiguousarray(np.arange(12.0).reshape(3, 4).T)
    for name, want in expected.items():
        path = os.path.join(d, name + '.npy')
        got = np.load(path)
        msg = objs.equal(got, want, name)
        if msg:
            fail(msg)
        compare_bytes(name, read(path), npy_bytes(want))
        np.save(os.path.join(d, 'py_' + name + '.npy'), got)


def check_objects(d):
    for name, want in (('annots', objs.annots()), ('params', objs.params())):
        path = os.path.join(d, name + '.npy')
        got = np.load(path, allow_pickle=True).item()
        msg = objs.equal(got, want, name)
        if msg:
            fail(msg)
        compare_bytes(name, read(path), npy_bytes(want), pickled=True)
        np.save(os.path.join(d, 'py_' + name + '.npy'), got)


PICKLE_OBJECTS = (('writer', objs.writer_object), ('big', objs.writer_big_object),
                  ('batches', objs.writer_batches_object))
DIGESTS = os.path.join(os.path.dirname(os.path.abspath(__file__)), 'pickle_digests.txt')


def sha256(data):
    return hashlib.sha256(data).hexdigest()


def read_digests():
    with open(DIGESTS) as f:
        return dict(line.split() for line in f if line.strip() and not line.startswith('#'))


def check_pickle(d):
    digests = read_digests()
    if not numpy1_format.REFERENCE_ENVIRONMENT:
        print('note: Python %d.%d, numpy %s: comparing with the digests of CPython 3.11 + numpy 1.x'
              % (sys.version_info[0], sys.version_info[1], np.__version__))
    for base, make in PICKLE_OBJECTS:
        for proto in (2, 3, 4):
            name = '%s_p%d.pkl' % (base, proto)
            data = read(os.path.join(d, name))
            msg = objs.equal(pickle.loads(data), make(), name)
            if msg:
                fail(msg)
            if numpy1_format.REFERENCE_ENVIRONMENT:
                want = pickle.dumps(make(), protocol=proto)
                compare_bytes(name, data, want, pickled=True)
                if sha256(want) != digests.get(name):
                    fail('%s: pickle.dumps no longer matches %s (rerun: check_io_written.py digests)'
                         % (name, DIGESTS))
            elif sha256(data) != digests.get(name):
                fail('%s: %d bytes, SHA-256 %s, not the bytes CPython 3.11 + numpy 1.x write (%s)'
                     % (name, len(data), sha256(data), digests.get(name)))


def write_digests(path):
    if not numpy1_format.REFERENCE_ENVIRONMENT:
        sys.exit('check_io_written.py digests: run with CPython 3.11 and numpy 1.x (Debian 12)')
    with open(path, 'w') as f:
        f.write('# SHA-256 of pickle.dumps(<object>, protocol) under CPython 3.11 + numpy 1.x, for the\n'
                '# byte checks of tests/io where another Python runs them (check_io_written.py digests).\n')
        for base, make in PICKLE_OBJECTS:
            for proto in (2, 3, 4):
                f.write('%s_p%d.pkl %s\n' % (base, proto, sha256(pickle.dumps(make(), protocol=proto))))


def check_sets(d):
    for proto in (2, 3, 4):
        got = pickle.loads(read(os.path.join(d, 'set_p%d.pkl' % proto)))
        if got != {'s': {1, 'a', (2, 3)}, 'e': set()}:
            fail('set_p%d.pkl: %r' % (proto, got))


def check_npz(d):
    with np.load(os.path.join(d, 'arrays.npz')) as z:
        if sorted(z.files) != ['a', 'b', 'c']:
            fail('arrays.npz keys %s' % z.files)
        for key, code in (('a', 'f8'), ('b', 'i4'), ('c', 'b1')):
            msg = objs.equal(z[key], objs.dtype_values(code), 'arrays.npz/' + key)
            if msg:
                fail(msg)
        np.savez_compressed(os.path.join(d, 'py_arrays.npz'), **{k: z[k] for k in z.files})


def main():
    mode = sys.argv[1]
    if mode == 'digests':
        write_digests(DIGESTS)
        return
    d = sys.argv[2]
    {'npy': check_npy, 'objects': check_objects, 'pickle': check_pickle, 'sets': check_sets,
     'npz': check_npz}[mode](d)
    if failures:
        print('%d mismatches' % len(failures))
        sys.exit(1)
    print('ok: %s' % mode)


if __name__ == '__main__':
    main()
