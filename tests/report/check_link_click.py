#!/usr/bin/env python3
"""A report link built from a hostile folder name, clicked in headless Chromium.

An evaluation folder may be named like a URL: `javascript:document.body.setAttribute(...);0`.
A page that wrote it into an href as it is would run that script when the link is clicked. This
writes a report page for such a folder with `transhuman-report page`, adds a script that clicks
the link to the folder's summary.json once the page is built, and checks with --dump-dom that
  - the script in the folder's name did not run (no data-pwned on <body>), and
  - the click opened the folder's summary.json as a file (the link is a relative path).
A control page with the same URL written raw into an href must show data-pwned: the check can
fail. Exits 77 (CTest's skip code) without Chromium. Standard library only.
"""
import argparse
import json
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from check_report_page import SKIP, begin, chromium, run  # noqa: E402

HOSTILE = "javascript:document.body.setAttribute('data-pwned','1');0"

# Clicks the first link whose target is a summary.json, after the page has built itself.
CLICKER = """<script>
window.addEventListener('load', () => setTimeout(() => {
  const a = [...document.querySelectorAll('a')].find((x) => (x.getAttribute('href') || '').endsWith('summary.json'));
  if (!a) { document.body.setAttribute('data-no-link', '1'); return; }
  a.click();
}, 300));
</script>
"""


def click_and_dump(browser, page):
    with open(page, encoding='utf-8') as f:
        text = f.read()
    clicked = os.path.join(os.path.dirname(page), 'clicked.html')
    with open(clicked, 'w', encoding='utf-8') as f:
        f.write(text.replace('</body>', CLICKER + '</body>'))
    dom, _, _ = chromium(browser, 'file://' + os.path.abspath(clicked), ['--dump-dom'])
    return dom


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument('--bin', required=True, help='build/apps')
    ap.add_argument('--work', required=True, help='scratch folder (emptied)')
    args = ap.parse_args()
    browser = begin(args.work)
    if not browser:
        return SKIP

    # An evaluation folder by that name: what the page reads from it.
    evaluation = os.path.join(args.work, HOSTILE)
    os.makedirs(evaluation)
    summary = {'setting': 'identity', 'images': 1, 'psnr': 21.5, 'ssim': 0.8, 'lpips': None,
               'lpips_available': 'no', 'seconds_per_image': 0.1}
    with open(os.path.join(evaluation, 'summary.json'), 'w') as f:
        json.dump(summary, f)
    with open(os.path.join(evaluation, 'per_image.csv'), 'w') as f:
        f.write('human,frame,view,psnr,ssim,lpips,seconds,points,culled_points,evaluated_points\n'
                'CoreView_s03,0,3,21.5,0.8,n/a,0.1,1,0,1\n')
    report = os.path.join(args.work, 'report')
    run([os.path.join(args.bin, 'transhuman-report'), 'page', '--out', report, '--eval', evaluation])

    failures = []
    dom = click_and_dump(browser, os.path.join(report, 'index.html'))
    if 'data-no-link' in dom:
        failures.append('the page has no link to the folder\'s summary.json')
    if 'data-pwned' in dom:
        failures.append('clicking the link ran the script in the folder\'s name')
    if '"psnr": 21.5' not in dom or 'th-errors' in dom:
        failures.append('the click did not open the folder\'s summary.json: ' + dom[:300])

    # The control: the same name as a raw href does run (so the check above can fail).
    control = os.path.join(args.work, 'control')
    os.makedirs(control)
    with open(os.path.join(control, 'index.html'), 'w', encoding='utf-8') as f:
        f.write('<!doctype html><html><body><a href="' + HOSTILE.replace('"', '&quot;') +
                '/summary.json">summary</a></body></html>')
    if 'data-pwned' not in click_and_dump(browser, os.path.join(control, 'index.html')):
        failures.append('control: a raw javascript: href did not run when clicked (the check cannot see it)')

    for f in failures:
        print('FAIL:', f)
    print('link click:', 'ok' if not failures else f'{len(failures)} failure(s)')
    return 1 if failures else 0


if __name__ == '__main__':
    sys.exit(main())
