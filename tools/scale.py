#!/usr/bin/env python3
"""Issue 13's scale table: encode time and peak memory against image size, per effort.

One Kodak image is fitted with 6000 Gaussians and rendered at 0.4, 1.6, 6.3 and 12 MP
(`gsi decode --width --height`: the same picture at every size, as in BENCHMARKS.md's
baseline); each size is then encoded at 1 bpp on the CPU at each effort, one encode at a
time, under /usr/bin/time (wall seconds, peak RSS). Prints a Markdown table; with --json
FILE also writes the rows there.

    python3 tools/scale.py [--efforts 1,5] [--sizes 768x512,4000x3000] [--json F] [IMAGE]

GSI_BIN names the binary (default target/release/gsi).
"""
import json, os, re, subprocess, sys, tempfile

root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
gsi = os.environ.get('GSI_BIN', root + '/target/release/gsi')
args = sys.argv[1:]


def option(name, default):
    if name in args:
        i = args.index(name)
        value = args[i + 1]
        del args[i:i + 2]
        return value
    return default


efforts = [int(e) for e in option('--efforts', '1,5').split(',')]
sizes = [tuple(int(v) for v in s.split('x'))
         for s in option('--sizes', '768x512,1536x1024,3072x2048,4000x3000').split(',')]
json_out = option('--json', None)
image = args[0] if args else root + '/../shared/data/kodak/kodim05.png'
work = tempfile.mkdtemp()


def run(cmd):
    r = subprocess.run(cmd, capture_output=True, text=True)
    if r.returncode != 0:
        sys.exit(f"{' '.join(cmd)} failed ({r.returncode}): {r.stderr.strip()}")
    return r


source = os.path.join(work, 'source.gsi')
run([gsi, 'encode', '--gaussians', '6000', '--device', 'cpu', '--quiet', image, '-o', source])
rows = []
print('| size | MP | effort | Gaussians | PSNR | wall | s per MP | peak RSS |')
print('|---|---|---|---|---|---|---|---|')
for (w, h) in sizes:
    png = os.path.join(work, f'{w}x{h}.png')
    run([gsi, 'decode', '--width', str(w), '--height', str(h), '--device', 'cpu', source, '-o', png])
    for e in efforts:
        out = os.path.join(work, 'out.gsi')
        timing = os.path.join(work, 'time')
        r = run(['/usr/bin/time', '-f', '%e %M', '-o', timing, gsi, 'encode', '--effort', str(e),
                 '--device', 'cpu', png, '-o', out])
        wall, rss_kb = open(timing).read().split()[-2:]
        summary = re.search(r'N (\d+) .*PSNR ([0-9.]+) dB', r.stderr + r.stdout)
        n, psnr = int(summary.group(1)), float(summary.group(2))
        mp = w * h / 1e6
        row = dict(width=w, height=h, megapixels=mp, effort=e, gaussians=n, psnr=psnr,
                   seconds=float(wall), peak_rss_mb=int(rss_kb) / 1024)
        rows.append(row)
        print(f"| {w}×{h} | {mp:.2f} | {e} | {n:,} | {psnr:.2f} dB | {row['seconds']:.1f} s "
              f"| {row['seconds'] / mp:.1f} | {row['peak_rss_mb']:.0f} MB |", flush=True)
if json_out:
    with open(json_out, 'w') as f:
        json.dump(dict(image=os.path.basename(image), binary=gsi, rows=rows), f, indent=1)
