#!/usr/bin/env python3
"""transhuman-view's HTTP API, on the trained tiny checkpoint.

Starts the viewer on a free port of 127.0.0.1 and checks:
  - /api/info and /api/frame describe the people, frames and cameras;
  - a render from a dataset camera's eye/forward/up/fovy is a PNG of the asked size, and a snap
    (camera=C) is the same image, byte for byte, as `transhuman-render --camera C`;
  - a snapped camera's PSNR and SSIM (/api/evaluate) equal transhuman-eval's for that view;
  - depth and opacity displays; a request older than one already seen is answered 409;
  - the frame's bake (/api/bake) gets ready, then baked views come as JPEG or PNG; an unbaked
    frame's baked view is 404;
  - bad requests get 400 and a message naming the parameter; paths outside the API get 404;
  - in headless Chromium, a drag of the camera brings fast views, then a refined one, and the
    image changes (the page's ?selftest=drag dispatches the mouse events);
and, as a server:
  - a Host that does not name the viewer is refused (421; also a DNS-rebinding name in Chromium),
    a cross-origin API request is refused (403: Origin, Sec-Fetch-Site; a cross-site <img> in
    Chromium), the viewer's own names and origin are answered;
  - request bodies are refused before they are read (413, the process does not grow), other
    methods get 405;
  - slow connections do not make it unreachable, and one that dribbles is closed;
  - /api/frame answers while a 512x512, 4096-sample render runs; a render whose client went away
    is cancelled; a render past --render-timeout is stopped with a 503 naming the bound;
  - a second viewer on the same port exits 2 naming the port;
  - --host :: prints a URL that works and says where it listens; an unwritable k-means cache
    folder does not stop it;
  - SIGINT while a render runs stops it with exit 0 within seconds (the time is printed), as does
    SIGTERM;
and on a viewer of their own (--render-timeout 5, --max-size 1024), the bounds of bakes and baked
views:
  - 300 /api/bake requests over more frames than it keeps: its threads and memory stay as they
    were, at most 2 bakes wait and the older ones are dropped, an exact render asked next is
    served, and the latest frame asked for is baked;
  - more baked views at once than the bound: 503 with Retry-After; their clients hang up: the
    viewer's CPU time stops growing within a second or two;
  - a baked view past --render-timeout: 503 naming the bound.
Standard library only.
"""
import argparse
import csv
import http.client
import json
import os
import re
import shutil
import signal
import socket
import struct
import subprocess
import sys
import threading
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


def request(port, path, headers=None, method='GET', host='127.0.0.1', timeout=60):
    """(status, body text, elapsed seconds) of one request with these headers (Host as given)."""
    t0 = time.monotonic()
    conn = http.client.HTTPConnection(host, port, timeout=timeout)
    try:
        conn.request(method, path, headers=headers or {})
        r = conn.getresponse()
        return r.status, r.read().decode(errors='replace'), time.monotonic() - t0
    finally:
        conn.close()


def rss_kib(pid):
    with open(f'/proc/{pid}/status') as f:
        return next(int(line.split()[1]) for line in f if line.startswith('VmRSS:'))


def proc_status(pid, key):
    """A number of /proc/<pid>/status: Threads, VmSize (KiB), ..."""
    with open(f'/proc/{pid}/status') as f:
        return next(int(line.split()[1]) for line in f if line.startswith(key + ':'))


def cpu_seconds(pid):
    """User and system CPU time the process has used (/proc/<pid>/stat), seconds."""
    with open(f'/proc/{pid}/stat') as f:
        fields = f.read().rsplit(')', 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf('SC_CLK_TCK')


def answer_length(data):
    """The length of the HTTP answer that `data` begins with (headers and Content-Length bytes;
    without Content-Length, the answer ends when the connection closes)."""
    head, _, _ = data.partition(b'\r\n\r\n')
    m = re.search(rb'(?i)content-length: *(\d+)', head)
    return len(head) + 4 + int(m.group(1)) if m else float('inf')


def read_answer(sock):
    """One whole HTTP answer from `sock` (or what came before it closed), as text."""
    data = b''
    while b'\r\n\r\n' not in data or len(data) < answer_length(data):
        chunk = sock.recv(65536)
        if not chunk:
            break
        data += chunk
    return data.decode(errors='replace')


class Background:
    """A request in a thread: .result is (status, text) or ('error', reason) once it ends."""

    def __init__(self, port, path):
        self.result = None
        self.sock = None

        def run():
            try:
                self.sock = socket.create_connection(('127.0.0.1', port), timeout=120)
                self.sock.sendall(f'GET {path} HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\n\r\n'.encode())
                answer = read_answer(self.sock)
                head = answer.split('\r\n', 1)[0].split()
                self.result = (int(head[1]), answer.partition('\r\n\r\n')[2]) if head else \
                    ('error', 'connection closed without an answer')
            except OSError as e:
                self.result = ('error', str(e))

        self.thread = threading.Thread(target=run, daemon=True)
        self.thread.start()

    def abandon(self):
        self.sock.shutdown(socket.SHUT_RDWR)  # the FIN leaves now, though a thread waits in recv
        self.sock.close()

    def wait(self, timeout):
        self.thread.join(timeout)
        return self.result


def heavy_render_path(frame, cam, client='heavy', seq=1):
    """A 512x512 render at 4096 samples from a dataset camera's pose: many seconds on a CPU."""
    v = lambda x: ','.join(repr(float(a)) for a in x)
    return '/api/render?' + urllib.parse.urlencode({
        'human': 0, 'frame': frame, 'eye': v(cam['eye']), 'forward': v(cam['forward']), 'up': v(cam['up']),
        'fovy': cam['fovy'], 'width': 512, 'height': 512, 'samples': 4096, 'client': client, 'seq': seq})


def start_viewer(binary, args):
    """The viewer and the lines it printed up to and including its 'listening on' line."""
    proc = subprocess.Popen([binary, *args], stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    lines = []
    for line in proc.stdout:
        lines.append(line.rstrip())
        if 'listening on' in line:
            break
    # Drain the rest of its output so that it never blocks on a full pipe.
    rest = []
    threading.Thread(target=lambda: rest.extend(l.rstrip() for l in proc.stdout), daemon=True).start()
    return proc, lines, rest


def stop_timed(proc, sig):
    t0 = time.monotonic()
    proc.send_signal(sig)
    try:
        code = proc.wait(timeout=30)
    except subprocess.TimeoutExpired:
        proc.kill()
        code = 'hung'
    return code, time.monotonic() - t0


def check_as_server(port, pid, frame, cams, browser, work):
    """Host and Origin, bodies and methods, slow connections, Chromium's view of both."""
    own = f'127.0.0.1:{port}'
    for host in (f'evil.example:{port}', f'127.0.0.1:{port + 1}', 'evil.example', f'localhost.evil.example:{port}'):
        status, text, _ = request(port, '/api/info', {'Host': host})
        check(status == 421 and f"Host '{host}'" in text and '--allow-host' in text,
              f'Host {host}: 421 naming it ({status}: {text.strip()[:120]!r})')
    status, text, _ = request(port, '/', {'Host': f'evil.example:{port}'})
    check(status == 421, f'the page for Host evil.example: 421 ({status})')
    for host in (own, f'localhost:{port}', f'LOCALHOST:{port}', f'[::1]:{port}'):
        status, _, _ = request(port, '/api/info', {'Host': host})
        check(status == 200, f'Host {host}: answered ({status})')
    for origin in ('http://evil.example', f'http://evil.example:{port}', 'null', f'http://127.0.0.1:{port + 1}'):
        status, text, _ = request(port, '/api/info', {'Origin': origin})
        check(status == 403 and f"origin '{origin}'" in text, f'Origin {origin}: 403 naming it ({status}: {text.strip()!r})')
    status, _, _ = request(port, '/api/info', {'Origin': f'http://{own}'})
    check(status == 200, f'its own Origin: answered ({status})')
    for site, want in (('cross-site', 403), ('same-site', 403), ('same-origin', 200), ('none', 200)):
        status, text, _ = request(port, '/api/info', {'Sec-Fetch-Site': site})
        check(status == want, f'Sec-Fetch-Site: {site} on the API: {want} ({status}: {text.strip()[:100]!r})')
    status, _, _ = request(port, '/', {'Sec-Fetch-Site': 'cross-site'})
    check(status == 200, f'the page itself may be linked from another site ({status})')
    with socket.create_connection(('127.0.0.1', port), timeout=10) as s:
        s.sendall(b'GET /api/info HTTP/1.0\r\n\r\n')
        answer = read_answer(s)
    check(answer.startswith('HTTP/1.1 400') and 'no Host header' in answer, f'no Host header: 400 ({answer[:40]!r})')

    # A 1000 MiB body is refused from its headers, before it is read: the answer comes while the
    # client has sent nothing of it, and what the client then sends is not kept.
    before = rss_kib(pid)
    for method, extra in (('POST', ''), ('GET', ''), ('POST', 'Expect: 100-continue\r\n')):
        with socket.create_connection(('127.0.0.1', port), timeout=10) as s:
            t0 = time.monotonic()
            s.sendall(f'{method} /api/info HTTP/1.1\r\nHost: {own}\r\nContent-Length: 1048576000\r\n{extra}\r\n'.encode())
            answer = read_answer(s)
            sent = 0
            try:
                for _ in range(256):  # up to 64 MiB of the body
                    s.sendall(b'\0' * (1 << 18))
                    sent += 1 << 18
            except OSError:
                pass
        status = answer.split(' ', 2)[1] if answer.startswith('HTTP/') else answer[:40]
        check(status == '413' and 'nothing was read' in answer and time.monotonic() - t0 < 10,
              f'{method} with a 1000 MiB body{" (Expect: 100-continue)" if extra else ""}: 413 before the body '
              f'({status}; the connection took {sent >> 20} MiB before it closed)')
    with socket.create_connection(('127.0.0.1', port), timeout=10) as s:
        s.sendall(f'POST /api/info HTTP/1.1\r\nHost: {own}\r\nTransfer-Encoding: chunked\r\n\r\n'.encode())
        answer = read_answer(s)
    check(answer.startswith('HTTP/1.1 413'), f'a chunked body: 413 ({answer[:40]!r})')
    grown = rss_kib(pid) - before
    check(grown < 32 * 1024, f'refused bodies are not kept (the process grew {grown >> 10} MiB)')
    status, text, _ = request(port, '/api/info', method='PUT')
    check(status == 405 and 'GET' in text, f'PUT: 405 ({status}: {text.strip()!r})')

    # Twenty connections that send half a request and wait, and twenty that send nothing: the
    # viewer still answers at once; a request dribbled a byte a second is cut off.
    slow = []
    for i in range(40):
        s = socket.create_connection(('127.0.0.1', port), timeout=30)
        if i < 20:
            s.sendall(f'GET /api/info HTTP/1.1\r\nHost: {own}\r\nX-Slow: '.encode())
        slow.append(s)
    status, _, elapsed = request(port, '/api/info', timeout=30)
    check(status == 200 and elapsed < 3, f'with 40 slow connections open, /api/info answers ({status}, {elapsed:.2f} s)')
    for s in slow:
        s.close()
    with socket.create_connection(('127.0.0.1', port), timeout=30) as s:
        t0 = time.monotonic()
        s.sendall(f'GET /api/info HTTP/1.1\r\nHost: {own}\r\n'.encode())
        closed = None
        while time.monotonic() - t0 < 25:
            try:
                s.sendall(b'X')
                time.sleep(1)
            except OSError:
                closed = time.monotonic() - t0
                break
            s.setblocking(False)
            try:
                if s.recv(4096) == b'':
                    closed = time.monotonic() - t0
                    break
            except BlockingIOError:
                pass
            finally:
                s.setblocking(True)
    check(closed is not None and closed < 15, f'a request dribbled byte by byte is cut off ({closed and round(closed, 1)} s)')

    if not browser:
        print('skip: Chromium is not installed, DNS rebinding and a cross-site image are not tried')
        return

    def chromium(url, *flags):
        return subprocess.run([browser, '--headless', '--no-sandbox', '--disable-gpu', *flags,
                               '--user-data-dir=' + os.path.join(work, 'chromium-profile'),
                               '--virtual-time-budget=5000', '--dump-dom', url],
                              capture_output=True, text=True, timeout=120).stdout
    # DNS rebinding: a name an attacker resolves to 127.0.0.1.
    dom = chromium(f'http://evil.example:{port}/', '--host-resolver-rules=MAP evil.example 127.0.0.1')
    check(f"refused: Host 'evil.example:{port}'" in dom and 'TransHuman viewer' not in dom,
          'Chromium, evil.example mapped to 127.0.0.1: the page is refused (' + dom.strip()[-160:] + ')')
    # Another site's page embedding a view: Sec-Fetch-Site cross-site.
    src = f'http://127.0.0.1:{port}/api/reference?human=0&frame={frame}&index=0'
    page = ('data:text/html,<body><img src="' + src + '" onload="document.body.dataset.img=\'loaded\'" '
            'onerror="document.body.dataset.img=\'refused\'"></body>')
    dom = chromium(page)
    check('data-img="refused"' in dom, 'Chromium, another site\'s <img> of a reference view: refused (' +
          (re.search(r'data-img="\w+"', dom) or [dom.strip()[-120:]])[0] + ')')


def free_port():
    with socket.socket() as s:
        s.bind(('127.0.0.1', 0))
        return s.getsockname()[1]


def wait_baked(base, human, frame, seconds):
    """/api/bake's answer for the frame once it is ready or failed (or `seconds` have passed)."""
    deadline = time.monotonic() + seconds
    while True:
        answer = json.loads(get(base, '/api/bake', {'human': human, 'frame': frame})[1])
        if answer['state'] in ('ready', 'failed') or time.monotonic() > deadline:
            return answer
        time.sleep(0.2)


def check_bake_bounds(binary, common, checkpoint):
    """The bake queue and baked views' bounds, on a viewer of their own: the pose setting (2
    people of 4 frames: more frames than it keeps bakes of), --render-timeout 5 (long enough to tell
    a cancelled march from one stopped by the bound), --max-size 1024 (a baked view of many
    seconds)."""
    port = free_port()
    base = f'http://127.0.0.1:{port}'
    server, _, log = start_viewer(binary, [*common, 'eval.setting=pose', '--checkpoint', checkpoint, '--port',
                                           str(port), '--render-timeout', '5', '--max-size', '1024'])
    pid = server.pid
    try:
        info = json.loads(get(base, '/api/info')[1])
        # Every (person, frame) the viewer takes, from the range its 400 names; 8 of them.
        keys = []
        for h in range(len(info['humans'])):
            _, body = get(base, '/api/bake', {'human': h, 'frame': 1 << 20})
            m = re.search(rb"must be in \[0, (\d+)\]", body)
            keys += [(h, f) for f in range(int(m.group(1)) + 1)] if m else []
        keys = keys[:8]
        if len(keys) <= 4:
            check(False, f'the dataset has more frames than the viewer keeps bakes of ({keys})')
            return
        # 300 requests over 8 frames, each answered at once, on one connection.
        threads, vm = proc_status(pid, 'Threads'), proc_status(pid, 'VmSize')
        conn = http.client.HTTPConnection('127.0.0.1', port, timeout=30)
        answers = []
        t0 = time.monotonic()
        try:
            for i in range(300):
                h, f = keys[i % len(keys)]
                conn.request('GET', f'/api/bake?human={h}&frame={f}')
                r = conn.getresponse()
                answers.append((r.status, json.loads(r.read()) if r.status == 200 else {}))
        finally:
            conn.close()
        flood = time.monotonic() - t0
        threads_now, vm_now = proc_status(pid, 'Threads'), proc_status(pid, 'VmSize')
        print(f'time: 300 /api/bake requests over {len(keys)} frames: {flood:.2f} s; threads {threads} -> '
              f'{threads_now}, VmSize {vm >> 10} -> {vm_now >> 10} MiB', flush=True)
        queued = max((a.get('queued', 99) for _, a in answers), default=99)
        dropped = answers[-1][1].get('dropped', 0)
        check(all(s == 200 for s, _ in answers) and queued <= 2,
              f'300 /api/bake requests over {len(keys)} frames: at most 2 bakes wait ({queued})')
        check(dropped >= 250, f'the older bakes asked for are dropped ({dropped} of 300)')
        # A thread per request would add 300 threads and their 8 MiB stacks (2.4 GiB of VmSize).
        check(threads_now <= threads + 2 and vm_now - vm < 1 << 20,
              f'no thread per request: threads {threads} -> {threads_now}, VmSize {vm >> 10} -> {vm_now >> 10} MiB')
        # An exact view waits behind the bake in flight at most, not behind the queue.
        last_h, last_f = keys[299 % len(keys)]
        c = json.loads(get(base, '/api/frame', {'human': last_h, 'frame': last_f})[1])['cameras'][3]
        v = lambda x: ','.join(repr(float(a)) for a in x)
        look = {'human': last_h, 'frame': last_f, 'eye': v(c['eye']), 'forward': v(c['forward']), 'up': v(c['up']),
                'fovy': c['fovy'], 'width': 40, 'height': 30, 'seq': 1}
        status, _, elapsed = request(port, '/api/render?' + urllib.parse.urlencode(look), timeout=120)
        check(status == 200, f'an exact view asked right after is served ({status} in {elapsed:.1f} s)')
        t0 = time.monotonic()
        for h, f in (keys[298 % len(keys)], (last_h, last_f)):
            bake = wait_baked(base, h, f, 120)
        waited = time.monotonic() - t0
        baked = sum('viewer: baked' in l for l in log)
        check(bake['state'] == 'ready' and bake['queued'] == 0 and baked <= 4,
              f'the latest frames asked for are baked in {waited:.1f} s, {baked} bakes in all ({bake})')
        time.sleep(0.5)
        # (The bakes' memory stays with the allocator's arenas: VmSize is shown, not bounded here.)
        threads_now, vm_now = proc_status(pid, 'Threads'), proc_status(pid, 'VmSize')
        check(threads_now <= threads + 2, f'once they are baked, the threads are as they were (threads {threads} -> '
                                          f'{threads_now}, VmSize {vm >> 10} -> {vm_now >> 10} MiB)')

        # Baked views, 1024x1024 at 4096 samples: many seconds each.
        def heavy(client):
            return '/api/render?' + urllib.parse.urlencode({**look, 'width': 1024, 'height': 1024, 'samples': 4096,
                                                            'baked': 1, 'format': 'jpeg', 'client': client})
        bound = info['baked_views']
        views = [Background(port, heavy(f'baked{i}')) for i in range(bound)]
        time.sleep(1.0)
        conn = http.client.HTTPConnection('127.0.0.1', port, timeout=30)
        try:
            t0 = time.monotonic()
            conn.request('GET', heavy('one-more'))
            r = conn.getresponse()
            status, text, retry = r.status, r.read().decode(), r.getheader('Retry-After')
            elapsed = time.monotonic() - t0
        finally:
            conn.close()
        check(status == 503 and retry and f'{bound} baked views' in text and elapsed < 2,
              f'{bound + 1} baked views at once: the last gets 503 with Retry-After in {elapsed:.2f} s '
              f'({status}, Retry-After {retry}: {text.strip()!r})')
        cpu0 = cpu_seconds(pid)
        time.sleep(0.5)
        busy = (cpu_seconds(pid) - cpu0) / 0.5
        running = sum(b.result is None for b in views)
        for b in views:
            b.abandon()
        time.sleep(1.0)
        cpu0 = cpu_seconds(pid)
        time.sleep(1.0)
        after = cpu_seconds(pid) - cpu0
        print(f'time: CPU while {running} baked views run: {busy:.2f} s/s; 1-2 s after their clients hung up: '
              f'{after:.2f} s/s', flush=True)
        check(running == bound and busy > 0.3 and after < min(0.2, busy / 3),
              f'baked views whose clients hung up stop using CPU ({busy:.2f} -> {after:.2f} s/s, {running} ran)')
        check(any('a baked view was cancelled, its client went away' in l for l in log), 'the viewer says so')
        status, text, elapsed = request(port, heavy('alone'), timeout=60)
        check(status == 503 and '--render-timeout' in text and 'baked view' in text and elapsed < 9,
              f'a baked view past --render-timeout 5: 503 naming the bound in {elapsed:.1f} s ({status}: {text.strip()!r})')
    finally:
        code, seconds = stop_timed(server, signal.SIGINT)
        check(code == 0, f'SIGINT: exit 0 in {seconds:.2f} s ({code})')


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
    server, lines, log = start_viewer(os.path.join(args.bin, 'transhuman-view'),
                                      [*common, '--checkpoint', args.checkpoint, '--port', str(port)])
    base = f'http://127.0.0.1:{port}'
    browser = next((shutil.which(n) for n in (os.environ.get('TH_CHROMIUM', ''), 'chromium', 'chromium-browser')
                    if n and shutil.which(n)), None)
    try:
        line = next((l for l in lines if 'open http://' in l), '')
        check(f'open {base}/' in line, f'the viewer prints its URL ({line.strip()!r})')
        check(any(f'listening on 127.0.0.1 only' in l for l in lines), f'and where it listens ({lines[-1:]})')

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

        # The frame's bake: /api/bake starts it and reports its progress; once it is ready, baked
        # views come as JPEG or PNG of the asked size; a frame not baked answers 404.
        others = [f for h in info['humans'][:1] for f in h['frames'] if f != frame]
        if others:
            status, body = get(base, '/api/render', {**look, 'frame': others[0], 'baked': 1, 'seq': 200})
            check(status == 404 and b'not baked' in body, f'a baked view of a frame not baked: 404 ({status})')
        status, body = get(base, '/api/bake', {'human': 0, 'frame': frame})
        bake = json.loads(body) if status == 200 else {}
        check(status == 200 and bake.get('state') in ('baking', 'ready'), f'/api/bake starts the bake ({status}: {bake})')
        deadline = time.time() + 300
        while bake.get('state') == 'baking' and time.time() < deadline:
            time.sleep(0.2)
            bake = json.loads(get(base, '/api/bake', {'human': 0, 'frame': frame})[1])
        check(bake.get('state') == 'ready' and bake.get('bricks', 0) > 0 and bake.get('progress') == 1,
              f'the bake is ready ({bake})')
        status, img = get(base, '/api/render', {**look, 'baked': 1, 'format': 'jpeg', 'seq': 201})
        check(status == 200 and img[:3] == b'\xff\xd8\xff', f'a baked view as JPEG ({status})')
        # Each view says how long the server's stages took (Server-Timing), the march or the
        # render, then the encoding, and answers on a kept-alive connection.
        conn = http.client.HTTPConnection('127.0.0.1', port, timeout=120)
        try:
            timings = []
            for seq, extra in ((204, {'baked': 1, 'format': 'jpeg'}), (205, {})):
                conn.request('GET', '/api/render?' + urllib.parse.urlencode({**look, **extra, 'seq': seq}))
                r = conn.getresponse()
                r.read()
                timings.append((r.status, r.getheader('Server-Timing') or ''))
        finally:
            conn.close()
        stage = re.compile(r'^(march|render);dur=[0-9.]+, encode;dur=[0-9.]+$')
        check([s for s, _ in timings] == [200, 200] and timings[0][1].startswith('march;')
              and timings[1][1].startswith('render;') and all(stage.match(t) for _, t in timings),
              f'baked and exact views name their stages\' times on one connection ({timings})')
        status, img = get(base, '/api/render', {**look, 'baked': 1, 'mode': 'depth', 'seq': 206})
        check(status == 200 and png_size(img) == (40, 30), f'a baked depth view as a 40x30 PNG ({status})')
        status, body = get(base, '/api/render', {'human': 0, 'frame': frame, 'camera': 3, 'baked': 1, 'seq': 207})
        check(status == 400 and b"'baked' views take eye..height" in body, f'a baked snap is refused ({status})')

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

        check_as_server(port, server.pid, frame, cams, browser, args.work)

        # /api/frame reads data only: it answers while a long render runs (another frame, not
        # yet seen). The render's client then goes away: the render is cancelled, and another
        # page's render gets the renderer at once.
        heavy = Background(port, heavy_render_path(frame, c, client='heavy', seq=1))
        time.sleep(1.5)
        other = info['humans'][0]['frames'][-1]
        status, _, elapsed = request(port, f'/api/frame?human=0&frame={other}', timeout=30)
        check(status == 200 and elapsed < 5 and heavy.result is None,
              f'/api/frame answers while a 512x512, 4096-sample render runs ({status}, {elapsed:.2f} s)')
        heavy.abandon()
        status, _, elapsed = request(port, '/api/render?' + urllib.parse.urlencode({**look, 'client': 'next', 'seq': 1}),
                                     timeout=60)
        check(status == 200 and elapsed < 5,
              f'a render whose client went away is cancelled: the next render is served in {elapsed:.2f} s ({status})')
        check(any('its client went away' in l for l in log), 'the viewer says so')

        # A second viewer on the same port is refused, naming it.
        p = subprocess.run([os.path.join(args.bin, 'transhuman-view'), *common, '--checkpoint', args.checkpoint,
                            '--port', str(port)], capture_output=True, text=True, timeout=120)
        last = p.stderr.strip().splitlines()[-1] if p.stderr.strip() else ''
        check(p.returncode == 2 and f'port {port} is in use' in last,
              f'a second viewer on port {port}: exit 2 ({p.returncode}, {last!r})')
    finally:
        # SIGINT while a 512x512, 4096-sample render runs: the render is cancelled (its client is
        # told the viewer stops) and the viewer exits 0 within seconds.
        heavy = Background(port, heavy_render_path(frame, c, client='last', seq=1)) if 'c' in locals() else None
        time.sleep(1.5)
        code, seconds = stop_timed(server, signal.SIGINT)
        print(f'time: SIGINT to exit during a render: {seconds:.2f} s', flush=True)
        check(code == 0 and seconds < 10, f'SIGINT during a render stops the viewer with exit 0 ({code}, {seconds:.2f} s)')
        if heavy:
            result = heavy.wait(10)
            check(result is not None and result[0] in (503, 'error'),
                  f'the render in flight was stopped ({result and (result[0], result[1].strip()[:60])})')

    # --host :: (every interface): the printed URL works; an unwritable k-means cache folder (a
    # path below a file) does not stop it; a render past --render-timeout is stopped with a 503
    # naming the bound; SIGTERM during a render ends it within seconds.
    with socket.socket(socket.AF_INET6) as s6:
        s6.bind(('::', 0))
        port6 = s6.getsockname()[1]
    blocker = os.path.join(args.work, 'a_file')
    open(blocker, 'w').close()
    unwritable = [f'model.grouping.cache_dir={blocker}/kmeans_cache']
    server, lines, rest = start_viewer(os.path.join(args.bin, 'transhuman-view'),
                                       [*common, *unwritable, '--checkpoint', args.checkpoint, '--port', str(port6),
                                        '--host', '::', '--render-timeout', '2'])
    try:
        printed = '\n'.join(lines)
        m = re.search(r'open (http://\S+) in a browser', printed)
        check(m is not None and m.group(1) == f'http://127.0.0.1:{port6}/', f'--host :: prints a usable URL ({m and m.group(1)})')
        check(f'listening on every interface of this machine ([::], IPv4 and IPv6)' in printed,
              'it says where it listens: ' + (lines[-1] if lines else ''))
        if m:
            status, body = get(m.group(1).rstrip('/'), '/api/info')
            check(status == 200, f'the printed URL answers ({status})')
        status, text, _ = request(port6, '/api/info', host='::1')
        check(status == 200, f'so does [::1]:{port6} ({status})')
        status, img, _ = request(port6, '/api/render?' + urllib.parse.urlencode({**look, 'seq': 1}))
        check(status == 200, f'with an unwritable k-means cache folder, a view renders ({status}: {img[:80]!r})')
        status, text, elapsed = request(port6, heavy_render_path(frame, c), timeout=60)
        check(status == 503 and '--render-timeout' in text and elapsed < 10,
              f'a render past --render-timeout 2: 503 naming the bound in {elapsed:.1f} s ({status}: {text.strip()!r})')
    finally:
        heavy = Background(port6, heavy_render_path(frame, c, client='term', seq=1))
        time.sleep(0.5)
        code, seconds = stop_timed(server, signal.SIGTERM)
        print(f'time: SIGTERM to exit during a render: {seconds:.2f} s', flush=True)
        check(code == 0 and seconds < 10, f'SIGTERM during a render stops the viewer with exit 0 ({code}, {seconds:.2f} s)')
        time.sleep(0.2)
        check(not any('Traceback' in l or 'internal error' in l for l in rest), 'it printed no internal error')
    check_bake_bounds(os.path.join(args.bin, 'transhuman-view'), common, args.checkpoint)

    # --host '' (every IPv4 interface) prints a loopback URL; --allow-host adds a name.
    with socket.socket() as s4:
        s4.bind(('127.0.0.1', 0))
        port4 = s4.getsockname()[1]
    server, lines, rest = start_viewer(os.path.join(args.bin, 'transhuman-view'),
                                       [*common, '--checkpoint', args.checkpoint, '--port', str(port4), '--host', '',
                                        '--allow-host', 'Viewer.Example', '--allow-host', '[FD00::7]'])
    try:
        printed = '\n'.join(lines)
        check(f'open http://127.0.0.1:{port4}/ in a browser' in printed and
              'listening on every interface of this machine (0.0.0.0, IPv4)' in printed,
              "--host '' prints a usable URL and where it listens: " + ' | '.join(lines[-2:]))
        for host in (f'viewer.example:{port4}', f'[fd00::7]:{port4}'):
            status, _, _ = request(port4, '/api/info', {'Host': host})
            check(status == 200, f'--allow-host: Host {host} answered ({status})')
        status, _, _ = request(port4, '/api/info', {'Host': f'other.example:{port4}'})
        check(status == 421, f'another name still refused ({status})')
    finally:
        code, seconds = stop_timed(server, signal.SIGINT)
        check(code == 0, f'SIGINT when idle: exit 0 in {seconds:.2f} s ({code})')

    for flags, message in ((['--human', 'nobody'], "no person 'nobody' in setting"),
                           (['--frame', '100000'], '--frame 100000: '),
                           (['--allow-host', 'evil.example:80'], "--allow-host 'evil.example:80': give the name "
                                                                 'without a port'),
                           (['--allow-host', 'a b'], "--allow-host 'a b' is not a host name or address")):
        p = subprocess.run([os.path.join(args.bin, 'transhuman-view'), *common, '--checkpoint', args.checkpoint,
                            '--dry-run', *flags], capture_output=True, text=True)
        last = p.stderr.strip().splitlines()[-1] if p.stderr.strip() else ''
        check(p.returncode == 2 and message in last, f'{" ".join(flags)}: exit 2, {last!r}')
    print(f'viewer API: {len(failures)} failure(s)')
    return 1 if failures else 0


if __name__ == '__main__':
    sys.exit(main())
