#!/usr/bin/env python3
"""JPEG (libjpeg-turbo's cjpeg -optimize, 4:2:0) and WebP (cwebp, default method) at equal
bytes to the gsi files of bench/encode.json (the report's Kodak rows at 0.5 and 1 bpp): for
each image, the highest quality whose file is no larger than gsi's, decoded by djpeg/dwebp
and scored by `gsi compare` (PSNR on 8-bit RGB). Writes bench/rd_external.json and prints
the means.

    CODEC_BIN=/usr/bin python3 tools/rd_external.py [KODAK_DIR]

CODEC_BIN holds cjpeg, djpeg, cwebp and dwebp (Debian: libjpeg-turbo-progs, webp); cjpeg
reads the PPM that a lossless cwebp/dwebp round trip makes of each PNG.
"""
import json, os, subprocess, statistics, sys, tempfile
root=os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
R=os.environ.get('CODEC_BIN','/usr/bin')+'/'
env=dict(os.environ)
gsi=os.environ.get('GSI_BIN',root+'/target/release/gsi')
K=(sys.argv[1] if len(sys.argv)>1 else root+'/../shared/data/kodak')+'/'
rows=json.load(open(root+'/bench/encode.json'))['rows']
W=tempfile.mkdtemp()
def psnr(ref, img):
    out=subprocess.run([gsi,'compare',ref,img,'--json'],capture_output=True,text=True,env=env).stdout
    return json.loads(out)['psnr']
def best(encode, budget, lo=1, hi=100):
    # highest quality whose file fits the budget (binary search on the monotone size)
    ok=None
    while lo<=hi:
        q=(lo+hi)//2
        n=encode(q)
        if n<=budget: ok=(q,n); lo=q+1
        else: hi=q-1
    return ok
res=[]
for r in rows:
    if r['target_bpp'] not in (0.5,1.0): continue
    img=r['image']; ref=K+img; stem=img[:-4]
    ppm=f'{W}/{stem}.ppm'
    if not os.path.exists(ppm):
        subprocess.run([R+'cwebp','-quiet','-lossless','-exact',ref,'-o',f'{W}/{stem}-ll.webp'],check=True,env=env)
        subprocess.run([R+'dwebp','-quiet',f'{W}/{stem}-ll.webp','-ppm','-o',ppm],check=True,env=env)
    budget=r['bytes']
    def jpg(q):
        subprocess.run([R+'cjpeg','-quality',str(q),'-optimize','-outfile',W+'/t.jpg',ppm],check=True,env=env)
        return os.path.getsize(W+'/t.jpg')
    def webp(q):
        subprocess.run([R+'cwebp','-quiet','-q',str(q),ppm,'-o',W+'/t.webp'],check=True,env=env)
        return os.path.getsize(W+'/t.webp')
    out={'image':img,'target':r['target_bpp'],'gsi_bytes':budget,'gsi_psnr':r['psnr']}
    j=best(jpg,budget)
    if j:
        jpg(j[0]); subprocess.run([R+'djpeg','-outfile',W+'/t.ppm',W+'/t.jpg'],check=True,env=env)
        out['jpeg']=(j[0],j[1],psnr(ref,W+'/t.ppm'))
    w=best(webp,budget,0,100)
    if w:
        webp(w[0]); subprocess.run([R+'dwebp','-quiet',W+'/t.webp','-ppm','-o',W+'/t2.ppm'],check=True,env=env)
        out['webp']=(w[0],w[1],psnr(ref,W+'/t2.ppm'))
    res.append(out)
    print(out, flush=True)
json.dump(res,open(root+'/bench/rd_external.json','w'),indent=1)
for t in (0.5,1.0):
    g=[x for x in res if x['target']==t]
    jj=[x for x in g if 'jpeg' in x]; ww=[x for x in g if 'webp' in x]
    px=768*512
    print(t, 'gsi %.2f (%.3f bpp)'%(statistics.mean(x['gsi_psnr'] for x in g), statistics.mean(x['gsi_bytes']*8/px for x in g)),
          'cjpeg %.2f (%d of %d, %.3f bpp)'%(statistics.mean(x['jpeg'][2] for x in jj), len(jj), len(g), statistics.mean(x['jpeg'][1]*8/px for x in jj)),
          'cwebp %.2f (%d of %d, %.3f bpp)'%(statistics.mean(x['webp'][2] for x in ww), len(ww), len(g), statistics.mean(x['webp'][1]*8/px for x in ww)))
