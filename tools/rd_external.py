#!/usr/bin/env python3
"""gsi against libjpeg, WebP and AVIF at equal bytes, on photographs.

Each image of each set is encoded by gsi at each target bpp (the defaults otherwise);
then each other codec at the highest quality whose file is no larger than gsi's (a
binary search on the quality, whose size is monotone), decoded, and scored with
`gsi compare` (PSNR on 8-bit RGB). Writes bench/rd_external.json and prints, per set and
target, the mean bpp and PSNR of each codec, gsi's bits per Gaussian by attribute, and the
BD-rate of gsi against libjpeg and WebP.

    CODEC_BIN=/usr/bin AVIF_BIN=/path/to/avifenc python3 tools/rd_external.py \\
        [--set NAME=DIR ...] [--bpp 0.25,0.5,1,1.5] [--out bench/rd_external.json]

Without --set: kodak and photos12 from ../shared/data. CODEC_BIN holds cjpeg, djpeg,
cwebp and dwebp (Debian: libjpeg-turbo-progs, webp); AVIF_BIN is avifenc (Debian:
libavif-bin; aom at speed 8), whose decoder avifdec sits beside it; without it AVIF is
left out (its libraries on LD_LIBRARY_PATH where they are not installed). libjpeg is `cjpeg -optimize` (4:2:0), WebP `cwebp -m 6`. cjpeg reads a PPM
made from each PNG by a lossless WebP round trip.
"""
import argparse, glob, json, math, os, subprocess, statistics, tempfile

root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
data = os.path.join(root, '..', 'shared', 'data')
ap = argparse.ArgumentParser()
ap.add_argument('--set', action='append', default=[], help='NAME=DIR of PNG files')
ap.add_argument('--bpp', default='0.25,0.5,1,1.5')
ap.add_argument('--out', default=os.path.join(root, 'bench', 'rd_external.json'))
args = ap.parse_args()
sets = [s.split('=', 1) for s in args.set] or [
    ('kodak', os.path.join(data, 'kodak')), ('photos12', os.path.join(data, 'photos12'))]
targets = [float(b) for b in args.bpp.split(',')]
B = os.environ.get('CODEC_BIN', '/usr/bin') + '/'
gsi = os.environ.get('GSI_BIN', os.path.join(root, 'target', 'release', 'gsi'))
avifenc = os.environ.get('AVIF_BIN')
W = tempfile.mkdtemp()


def run(*cmd):
    return subprocess.run(cmd, check=True, capture_output=True, text=True).stdout


def psnr(ref, img):
    return json.loads(run(gsi, 'compare', ref, img, '--json'))['psnr']


def best(encode, budget, lo, hi):
    """Highest quality whose file fits the budget: (quality, bytes) or None."""
    ok = None
    while lo <= hi:
        q = (lo + hi) // 2
        n = encode(q)
        if n <= budget:
            ok, lo = (q, n), q + 1
        else:
            hi = q - 1
    return ok


def codecs(ppm):
    def jpeg(q):
        run(B + 'cjpeg', '-quality', str(q), '-optimize', '-outfile', W + '/t.jpg', ppm)
        return os.path.getsize(W + '/t.jpg')

    def webp(q):
        run(B + 'cwebp', '-quiet', '-m', '6', '-q', str(q), ppm, '-o', W + '/t.webp')
        return os.path.getsize(W + '/t.webp')

    def avif(q):
        # Quality q is quantizer 63 − q (0 is lossless).
        qz = str(63 - q)
        run(avifenc, '-s', '8', '-j', '1', '--min', qz, '--max', qz, ppm + '.png', W + '/t.avif')
        return os.path.getsize(W + '/t.avif')

    def decoded(out, *cmd):
        run(*cmd)
        return out

    d = W + '/d.ppm'
    out = [('jpeg', jpeg, 1, 100, lambda: decoded(d, B + 'djpeg', '-outfile', d, W + '/t.jpg')),
           ('webp', webp, 0, 100, lambda: decoded(d, B + 'dwebp', '-quiet', W + '/t.webp', '-ppm', '-o', d))]
    if avifenc:
        avifdec = os.path.join(os.path.dirname(avifenc), 'avifdec')
        out.append(('avif', avif, 0, 63, lambda: decoded(W + '/d.png', avifdec, W + '/t.avif', W + '/d.png')))
    return out


res = []
for name, folder in sets:
    for img in sorted(glob.glob(os.path.join(folder, '*.png'))):
        stem = os.path.basename(img)[:-4]
        ppm = f'{W}/{stem}.ppm'
        run(B + 'cwebp', '-quiet', '-lossless', '-exact', img, '-o', f'{W}/ll.webp')
        run(B + 'dwebp', '-quiet', f'{W}/ll.webp', '-ppm', '-o', ppm)
        run(B + 'dwebp', '-quiet', f'{W}/ll.webp', '-o', ppm + '.png')
        for t in targets:
            g = f'{W}/{stem}.gsi'
            run(gsi, 'encode', img, '-o', g, '--bpp', str(t), '--quiet')
            info = json.loads(run(gsi, 'info', g, '--json'))
            run(gsi, 'decode', g, '-o', f'{W}/g.png', '--device', 'cpu')
            budget = os.path.getsize(g)
            px = info['width'] * info['height']
            row = {'set': name, 'image': os.path.basename(img), 'target': t, 'pixels': px,
                   'gsi': [budget, psnr(img, f'{W}/g.png')], 'gaussians': info['gaussians'],
                   'bits_per_gaussian': info['bits_per_gaussian'],
                   'color_bits': info['quantizers']['GCOL'][0]['bits']}
            for codec, enc, lo, hi, dec in codecs(ppm):
                found = best(enc, budget, lo, hi)
                if found:
                    enc(found[0])
                    row[codec] = [found[1], psnr(img, dec()), found[0]]
            res.append(row)
            print(json.dumps(row), flush=True)
json.dump(res, open(args.out, 'w'), indent=1)


def bd_rate(a, b):
    """Mean bitrate difference of curve a against b over the PSNR range both cover,
    piecewise-linear in log rate; points are (bpp, psnr) in rising order."""
    lo = max(a[0][1], b[0][1])
    hi = min(a[-1][1], b[-1][1])
    if hi <= lo:
        return None

    def log_rate(c, p):
        for (r0, p0), (r1, p1) in zip(c, c[1:]):
            if p0 <= p <= p1 and p1 > p0:
                return math.log(r0) + (math.log(r1) - math.log(r0)) * (p - p0) / (p1 - p0)
        return math.log(c[0][0]) if p <= c[0][1] else math.log(c[-1][0])

    steps = 200
    d = sum(log_rate(a, lo + (hi - lo) * (i + 0.5) / steps) - log_rate(b, lo + (hi - lo) * (i + 0.5) / steps)
            for i in range(steps)) / steps
    return math.exp(d) - 1


names = ['gsi', 'jpeg', 'webp'] + (['avif'] if avifenc else [])
print('| set | bpp | gsi | libjpeg | WebP |' + (' AVIF |' if avifenc else '') +
      ' gsi bits/Gaussian (GPOS, GCOV, GCOL) | colour bits |')
print('|---|---|---|---|---|' + ('---|' if avifenc else '') + '---|---|')
curves = {}
for name, _ in sets:
    for t in targets:
        rows = [r for r in res if r['set'] == name and r['target'] == t]
        cells = []
        for c in names:
            have = [r for r in rows if c in r]
            if not have:
                cells.append('-')
                continue
            bpp = statistics.mean(r[c][0] * 8 / r['pixels'] for r in have)
            p = statistics.mean(r[c][1] for r in have)
            # A codec that cannot reach some files' size is scored on the others only.
            if len(have) == len(rows):
                curves.setdefault((name, c), []).append((bpp, p))
            cells.append(f'{p:.2f} ({bpp:.3f})' + ('' if len(have) == len(rows) else f' {len(have)} of {len(rows)}'))
        bits = {k: statistics.mean(r['bits_per_gaussian'][k] for r in rows) for k in ('GPOS', 'GCOV', 'GCOL')}
        col = sorted({r['color_bits'] for r in rows})
        print(f'| {name} | {t} | ' + ' | '.join(cells) +
              f' | {sum(bits.values()):.1f} ({bits["GPOS"]:.1f}, {bits["GCOV"]:.1f}, {bits["GCOL"]:.1f}) | '
              f'{min(col)}' + (f'–{max(col)}' if max(col) > min(col) else '') + ' |')
for name, _ in sets:
    g = sorted(curves.get((name, 'gsi'), []))
    for c in names[1:]:
        o = sorted(curves.get((name, c), []))
        bd = bd_rate(g, o) if len(g) > 1 and len(o) > 1 else None
        print(f'BD-rate of gsi against {c} on {name}: ' + ('n/a' if bd is None else f'{100 * bd:+.1f} %'))
