#!/usr/bin/env python3
"""Latency of transhuman-view on a trained checkpoint: for N drags around the person, the time
from a camera move to its fast image (128 px on the long side, 16 samples, what the page asks
for while the camera moves) and to its refined image (the view's full size at the configured
samples, what the page asks for when the camera rests); the frame's bake (from /api/bake's first
ask until it is ready) and a baked view at the full size after a move (what the page asks for
while moving once the frame is baked); in headless Chromium, the views the page shows per
second while the camera is dragged (its ?selftest=fps, a mouse move every 16 ms); and the
server's memory. Prints the figures and appends them to bench/results/viewer.md.

  bench/viewer_latency.py --checkpoint runs/demo/checkpoints/latest.pt [--config configs/demo.yaml]
                          [--drags 20] [--refined 5] [--bin build/apps] [--fps-seconds 10]
                          [-- overrides...]
"""
import argparse
import datetime
import json
import math
import os
import socket
import statistics
import subprocess
import sys
import time
import urllib.parse
import urllib.request


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument('--bin', default='build/apps')
    ap.add_argument('--config', default='configs/demo.yaml')
    ap.add_argument('--checkpoint', required=True)
    ap.add_argument('--drags', type=int, default=20)
    ap.add_argument('--refined', type=int, default=5, help='drags that also wait for the refined image')
    ap.add_argument('--threads', type=int, default=2)
    ap.add_argument('--fps-seconds', type=float, default=10, help='length of the drag in Chromium (0: none)')
    ap.add_argument('overrides', nargs='*')
    args = ap.parse_args()
    with socket.socket() as s:
        s.bind(('127.0.0.1', 0))
        port = s.getsockname()[1]
    server = subprocess.Popen([os.path.join(args.bin, 'transhuman-view'), '--config', args.config, '--checkpoint',
                               args.checkpoint, '--port', str(port), '--threads', str(args.threads), *args.overrides],
                              stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    base = f'http://127.0.0.1:{port}'
    try:
        for line in server.stdout:
            if 'open http://' in line:
                break
        get = lambda path, q: urllib.request.urlopen(base + path + '?' + urllib.parse.urlencode(q), timeout=600).read()
        info = json.loads(get('/api/info', {}))
        frame = info['humans'][0]['frames'][0]
        t0 = time.perf_counter()
        fr = json.loads(get('/api/frame', {'human': 0, 'frame': frame}))
        prepare = time.perf_counter() - t0
        cam = fr['cameras'][info['view']]
        center = fr['center']
        eye0 = [e - c for e, c in zip(cam['eye'], center)]
        up = cam['up']
        w0, h0 = int(cam['width']), int(cam['height'])
        scale = min(1.0, 128 / max(w0, h0))
        fast_wh = (max(8, round(w0 * scale)), max(8, round(h0 * scale)))
        t0 = time.perf_counter()
        while json.loads(get('/api/bake', {'human': 0, 'frame': frame}))['state'] == 'baking':
            time.sleep(0.05)
        bake = json.loads(get('/api/bake', {'human': 0, 'frame': frame}))
        bake_seconds = time.perf_counter() - t0
        fast, refined, baked, stages, seq = [], [], [], [], 0
        # Rotate the eye about the up axis through the centre: one drag step per 10 degrees.
        u = [x / math.sqrt(sum(y * y for y in up)) for x in up]
        for k in range(args.drags):
            a = math.radians(10 * (k + 1))
            ca, sa = math.cos(a), math.sin(a)
            dot = sum(p * q for p, q in zip(u, eye0))
            cross = [u[1] * eye0[2] - u[2] * eye0[1], u[2] * eye0[0] - u[0] * eye0[2], u[0] * eye0[1] - u[1] * eye0[0]]
            rel = [eye0[i] * ca + cross[i] * sa + u[i] * dot * (1 - ca) for i in range(3)]
            eye = [c + r for c, r in zip(center, rel)]
            forward = [-r for r in rel]
            q = {'human': 0, 'frame': frame, 'eye': ','.join(map(repr, eye)), 'forward': ','.join(map(repr, forward)),
                 'up': ','.join(map(repr, up)), 'fovy': cam['fovy'], 'client': 'bench'}
            seq += 1
            t0 = time.perf_counter()
            get('/api/render', {**q, 'width': fast_wh[0], 'height': fast_wh[1], 'samples': 16, 'seq': seq})
            fast.append(time.perf_counter() - t0)
            if bake['state'] == 'ready':
                seq += 1
                t0 = time.perf_counter()
                with urllib.request.urlopen(base + '/api/render?' + urllib.parse.urlencode(
                        {**q, 'width': w0, 'height': h0, 'baked': 1, 'format': 'jpeg', 'seq': seq}), timeout=600) as r:
                    r.read()
                    stages.append(dict(m.strip().split(';dur=') for m in r.headers['Server-Timing'].split(',')))
                baked.append(time.perf_counter() - t0)
            if k < args.refined:
                seq += 1
                t1 = time.perf_counter()
                get('/api/render', {**q, 'width': w0, 'height': h0, 'seq': seq})
                refined.append(time.perf_counter() - t0)  # from the move, as the user waits
                _ = t1
        fps = chromium_fps(base, args.fps_seconds) if args.fps_seconds > 0 else None
        with open(f'/proc/{server.pid}/status') as f:
            mem = {l.split(':')[0]: l.split(':')[1].strip() for l in f if l.startswith(('VmRSS', 'VmHWM'))}
    finally:
        server.terminate()
        server.wait(timeout=60)
    commit = subprocess.run(['git', 'rev-parse', '--short', 'HEAD'], capture_output=True, text=True).stdout.strip()
    cpu = next((l.split(':', 1)[1].strip() for l in open('/proc/cpuinfo') if l.startswith('model name')), '?')
    load = open('/proc/loadavg').read().split()[0]
    fmt = lambda xs: f'median {statistics.median(xs):.2f} s, worst {max(xs):.2f} s ({len(xs)} drags)'
    lines = [
        f'## {datetime.date.today()} · {commit} · {cpu} · {args.threads} threads · load {load}',
        '',
        f'`{args.config}`, checkpoint `{args.checkpoint}`, overrides {args.overrides or "none"}; '
        f'{info["humans"][0]["name"]} frame {frame}, view {info["view"]} ({w0}x{h0})',
        '',
        f'- first view of the frame (its preparation, via /api/frame): {prepare:.2f} s',
        f'- fast image ({fast_wh[0]}x{fast_wh[1]}, 16 samples) after a move: {fmt(fast)}',
        f'- refined image ({w0}x{h0}, {info["samples"]} samples) after a move: {fmt(refined)}',
        f'- the frame\'s bake (/api/bake until ready): {bake_seconds:.2f} s, {bake["state"]}'
        + (f', {bake["bricks"]} bricks, {bake["mib"]:.1f} MiB, {100 * bake["voxel"]:.1f} cm grid' if bake['state'] == 'ready' else ''),
        f'- baked image ({w0}x{h0}, JPEG) after a move: '
        + (f'median {1e3 * statistics.median(baked):.1f} ms, worst {1e3 * max(baked):.1f} ms ({len(baked)} drags); '
           f'the server\'s part (Server-Timing, medians): march {statistics.median(float(s["march"]) for s in stages):.1f} ms, '
           f'encode {statistics.median(float(s["encode"]) for s in stages):.1f} ms' if baked else 'none'),
        f'- in headless Chromium while dragging: {fps or "not measured"}',
        f'- server memory: resident {mem.get("VmRSS")}, peak {mem.get("VmHWM")}',
        '',
    ]
    text = '\n'.join(lines)
    print(text)
    os.makedirs('bench/results', exist_ok=True)
    path = 'bench/results/viewer.md'
    new = not os.path.exists(path)
    with open(path, 'a') as f:
        if new:
            f.write('# transhuman-view latency (bench/viewer_latency.py)\n\n')
        f.write(text + '\n')
    return 0


def chromium_fps(base, seconds):
    """The page's ?selftest=fps in headless Chromium, in real time: the title it sets when done,
    read from Chromium's DevTools list of pages."""
    import shutil
    import tempfile
    browser = shutil.which('chromium') or shutil.which('chromium-browser')
    if not browser:
        return 'Chromium not installed'
    flags = ['--headless', '--no-sandbox', '--disable-gpu', '--disable-quic', '--no-first-run',
             '--disable-background-networking', '--disable-component-update', '--disable-sync',
             '--window-size=1100,800']
    with socket.socket() as s:
        s.bind(('127.0.0.1', 0))
        port = s.getsockname()[1]
    result = 'the page reported nothing'
    with tempfile.TemporaryDirectory() as profile:
        proc = subprocess.Popen([browser, *flags, '--user-data-dir=' + profile, f'--remote-debugging-port={port}',
                                 f'{base}/?selftest=fps&seconds={seconds}'],
                                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        try:
            deadline = time.time() + seconds + 120
            while time.time() < deadline:
                time.sleep(0.5)
                try:
                    pages = json.loads(urllib.request.urlopen(f'http://127.0.0.1:{port}/json/list', timeout=5).read())
                except OSError:
                    continue
                titles = [p.get('title', '') for p in pages if p.get('type') == 'page']
                done = [t for t in titles if t.startswith('fps: ')]
                if done:
                    result = done[0][5:]
                    break
        finally:
            proc.terminate()
            proc.wait(timeout=30)
    return result


if __name__ == '__main__':
    sys.exit(main())
