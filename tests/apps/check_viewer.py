#!/usr/bin/env python3
"""transhuman-view's HTTP API, on the trained tiny checkpoint.

Starts the viewer on a free port of 127.0.0.1 and checks:
  - /api/info and /api/frame describe the people, frames and cameras;
  - a render from a dataset camera's eye/forward/up/fovy is a PNG of the asked size, and a snap
    (camera=C) is the same image, byte for byte, as `transhuman-render --camera C`;
  - a snapped camera's PSNR and SSIM (/api/evaluate) equal transhuman-eval's for that view;
  - depth and opacity displays; a request older than one already seen is answered 409;
  - bad requests get 400 and a message naming the parameter; paths outside the API get 404;
  - in headless Chromium, a drag of the camera brings fast views, then a refined one, and the
    image changes (the page's ?selftest=drag dispatches the mouse events);
  - SIGINT stops the server with exit 0.
Standard library only.
"""
import argparse
import csv
import json
import os
import re
import shutil
import signal
import socket
import struct
import subprocess
import sys
import time
import urllib.error
import urllib.parse
import urllib.request

failures = []


def check(cond, what):
    print(('ok: ' if cond else 'FAIL: ') + what, flush=True)
    if not cond:
        failures.append(what)


def get(base, path, params=None):
    url = base + path + ('?' + urllib.parse.urlencode(params) if params else '')
    try:
        with urllib.request.urlopen(url, timeout=120) as r:
            return r.status, r.read()
    except urllib.error.HTTPError as e:
        return e.code, e.read()


def png_size(data):
    if data[:8] != b'\x89PNG\r\n\x1a\n':
        return None
    return struct.unpack('>II', data[16:24])


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument('--bin', required=True)
    ap.add_argument('--data', required=True)
    ap.add_argument('--checkpoint', required=True)
    ap.add_argument('--work', required=True)
    args = ap.parse_args()
    shutil.rmtree(args.work, ignore_errors=True)
    os.makedirs(args.work)
    common = ['--config', 'tests/configs/tiny_surface.yaml', '--threads', '1', f'data.root={args.data}',
              f'data.split_file={args.data}/split.yaml',
              f'model.grouping.cache_dir={os.path.dirname(args.data)}/kmeans_cache']
    with socket.socket() as s:
        s.bind(('127.0.0.1', 0))
        port = s.getsockname()[1]
    server = subprocess.Popen([os.path.join(args.bin, 'transhuman-view'), *common, '--checkpoint', args.checkpoint,
                               '--port', str(port)], stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    base = f'http://127.0.0.1:{port}'
    try:
        line = ''
        for line in server.stdout:
            if 'open http://' in line:
                break
        check(f'open {base}/' in line, f'the viewer prints its URL ({line.strip()!r})')

        status, body = get(base, '/api/info')
        info = json.loads(body)
        check(status == 200 and len(info['humans']) >= 1 and info['humans'][0]['frames'], 'info lists people and frames')
        check(info['start'] == {'human': 0, 'frame': -1}, f"info says what to show first ({info['start']})")
        frame = info['humans'][0]['frames'][0]
        status, body = get(base, '/api/frame', {'human': 0, 'frame': frame})
        fr = json.loads(body)
        cams = fr['cameras']
        check(status == 200 and len(cams) == info['humans'][0]['cameras'] and len(fr['center']) == 3,
              'frame describes every dataset camera and the body centre')
        c = cams[3]
        v = lambda x: ','.join(repr(float(a)) for a in x)
        look = {'human': 0, 'frame': frame, 'eye': v(c['eye']), 'forward': v(c['forward']), 'up': v(c['up']),
                'fovy': c['fovy'], 'width': 40, 'height': 30, 'seq': 1}
        status, img = get(base, '/api/render', look)
        check(status == 200 and png_size(img) == (40, 30), f'a 40x30 render from camera 3\'s pose ({status})')
        for mode in ('depth', 'acc'):
            status, img = get(base, '/api/render', {**look, 'mode': mode, 'seq': 2})
            check(status == 200 and png_size(img) == (40, 30), f'the {mode} display')
        status, _ = get(base, '/api/render', {**look, 'seq': 1})
        check(status == 409, f'a request older than one already seen is cancelled (409, got {status})')

        # A snap is transhuman-render's image of that camera, byte for byte.
        status, snap = get(base, '/api/render', {'human': 0, 'frame': frame, 'camera': 3, 'seq': 3})
        out = os.path.join(args.work, 'render')
        subprocess.run([os.path.join(args.bin, 'transhuman-render'), *common, '--checkpoint', args.checkpoint,
                        '--out', out, '--camera', '3', '--human', info['humans'][0]['name'], '--frames', str(frame)],
                       check=True, capture_output=True)
        with open(os.path.join(out, 'frames', 'frame_0000.png'), 'rb') as f:
            rendered = f.read()
        check(status == 200 and png_size(snap) == png_size(rendered), 'a snap has the dataset camera\'s size')
        import zlib  # the decoded pixels: PNG encoders may differ in filters, not in pixels

        def pixels(data):
            pos, idat = 8, b''
            while pos < len(data):
                n, kind = struct.unpack('>I4s', data[pos:pos + 8])
                if kind == b'IDAT':
                    idat += data[pos + 8:pos + 8 + n]
                pos += 12 + n
            return zlib.decompress(idat)
        check(status == 200 and pixels(snap) == pixels(rendered), 'a snap equals transhuman-render --camera 3')

        # A snapped camera's PSNR and SSIM are transhuman-eval's for that view.
        ev_out = os.path.join(args.work, 'eval')
        subprocess.run([os.path.join(args.bin, 'transhuman-eval'), *common, '--checkpoint', args.checkpoint,
                        '--out', ev_out, 'eval.limit=1', 'eval.save_images=false'], check=True, capture_output=True)
        with open(os.path.join(ev_out, 'per_image.csv')) as f:
            row = next(csv.DictReader(f))
        names = [h['name'] for h in info['humans']]
        status, body = get(base, '/api/evaluate', {'human': names.index(row['human']), 'frame': row['frame'],
                                                   'camera': row['view']})
        score = json.loads(body) if status == 200 else {}
        check(status == 200 and abs(score['psnr'] - float(row['psnr'])) < 1e-5 and
              abs(score['ssim'] - float(row['ssim'])) < 1e-5,
              f"a snap's PSNR/SSIM equal transhuman-eval's ({score} against {row['psnr']}, {row['ssim']})")
        status, gt = get(base, '/api/ground_truth', {'human': 0, 'frame': frame, 'camera': 3})
        check(status == 200 and png_size(gt) == png_size(rendered), 'the ground truth of a dataset camera')

        status, ref = get(base, '/api/reference', {'human': 0, 'frame': frame, 'index': 0})
        check(status == 200 and png_size(ref) is not None, 'a reference view as PNG')

        bad = [
            ({k: x for k, x in look.items() if k != 'eye'}, "missing parameter 'eye'"),
            ({**look, 'eye': 'nan,0,0'}, "'eye' holds 'nan', not a finite number"),
            ({**look, 'eye': '1,2'}, "'eye' = '1,2' must be three numbers"),
            ({**look, 'forward': '0,0,0'}, "'forward' must not be zero"),
            ({**look, 'up': v(c['forward'])}, "'up' must not be zero or parallel to 'forward'"),
            ({**look, 'width': 100000}, "'width' = 100000 must be in [8, 512]"),
            ({**look, 'samples': 1}, "'samples' = 1 must be in [2, 4096]"),
            ({**look, 'human': 99}, "'human' = 99 must be in [0, "),
            ({**look, 'frame': -1}, "'frame' = -1 must be in [0, "),
            ({**look, 'fovy': 179}, "'fovy' = 179 must be in [1, 170] degrees"),
            ({**look, 'mode': 'x'}, "'mode' = 'x' must be rgb, depth or acc"),
            ({**look, 'camera': 99}, "'camera' = 99 must be in [0, "),
        ]
        for params, message in bad:
            status, body = get(base, '/api/render', {**params, 'seq': 100})
            check(status == 400 and message in body.decode(), f'400 "{message}" ({status}: {body.decode().strip()!r})')
        for path in ('/etc/passwd', '/three/../../etc/passwd', '/api/../etc/passwd', '/three/foo.js'):
            status, _ = get(base, path)
            check(status == 404, f'{path}: 404 ({status})')
        status, page = get(base, '/')
        check(status == 200 and b'OrbitControls' in page, 'the page')

        # The page in headless Chromium: a drag (dispatched mouse events, ?selftest=drag) brings
        # fast views while the camera moves, then a refined one, and the image changes.
        browser = next((shutil.which(n) for n in (os.environ.get('TH_CHROMIUM', ''), 'chromium', 'chromium-browser')
                        if n and shutil.which(n)), None)
        if browser:
            dom = subprocess.run([browser, '--headless', '--no-sandbox', '--disable-gpu',
                                  '--user-data-dir=' + os.path.join(args.work, 'chromium-profile'),
                                  '--virtual-time-budget=20000', '--dump-dom', base + '/?selftest=drag'],
                                 capture_output=True, text=True, timeout=180).stdout
            m = re.search(r'data-selftest="fast views while moving: (\d+); refined: yes; image changed: (\w+)"', dom)
            check(m is not None and int(m.group(1)) > 0 and m.group(2) == 'yes',
                  'a drag in Chromium re-renders: ' + (m.group(0) if m else 'no result: ' + dom[-300:]))
        else:
            print('skip: Chromium is not installed, the drag is not checked')
    finally:
        server.send_signal(signal.SIGINT)
        try:
            code = server.wait(timeout=30)
        except subprocess.TimeoutExpired:
            server.kill()
            code = 'hung'
        check(code == 0, f'SIGINT stops the viewer with exit 0 ({code})')
    for flags, message in ((['--human', 'nobody'], "no person 'nobody' in setting"),
                           (['--frame', '100000'], '--frame 100000: ')):
        p = subprocess.run([os.path.join(args.bin, 'transhuman-view'), *common, '--checkpoint', args.checkpoint,
                            '--dry-run', *flags], capture_output=True, text=True)
        last = p.stderr.strip().splitlines()[-1] if p.stderr.strip() else ''
        check(p.returncode == 2 and message in last, f'{" ".join(flags)}: exit 2, {last!r}')
    print(f'viewer API: {len(failures)} failure(s)')
    return 1 if failures else 0


if __name__ == '__main__':
    sys.exit(main())
