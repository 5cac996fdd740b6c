# The noisy 1280x1080 speed pairs of the DIC comparison: Gaussian dots integrated analytically
# (no interpolated raster), 16-bit, noise 0.5 % of full scale; a (64.3, 0.4) px translation and a
# 1 % x stretch + 0.5 deg rotation about the centre. Usage: python make_pair.py (writes ref.tif,
# trans.tif, stretchrot.tif into the folder given, default the current one; needs numpy, tifffile).
import numpy as np, tifffile, math, os, sys
out = sys.argv[1] if len(sys.argv) > 1 else '.'
os.makedirs(out, exist_ok=True)
W,H=1280,1080
rng=np.random.default_rng(1)
sp=5.0; sig=1.3
xs=np.arange(-100,W+100,sp); ys=np.arange(-100,H+100,sp)
X,Y=np.meshgrid(xs,ys)
X=X.ravel()+rng.random(X.size)*sp; Y=Y.ravel()+rng.random(Y.size)*sp
D=90*(1+0.3*(2*rng.random(X.size)-1))
def render(px,py,sx,sy):
    img=np.zeros((H,W))
    r=int(math.ceil(4*max(sx,sy)))
    offs=np.arange(-r,r+1)
    for k in range(px.size):
        cx,cy=px[k],py[k]
        ix=int(round(cx)); iy=int(round(cy))
        if ix< -r or iy< -r or ix>=W+r or iy>=H+r: continue
        x0=max(ix-r,0); x1=min(ix+r+1,W); y0=max(iy-r,0); y1=min(iy+r+1,H)
        if x0>=x1 or y0>=y1: continue
        gx=np.exp(-(np.arange(x0,x1)-cx)**2/(2*sx*sx)); gy=np.exp(-(np.arange(y0,y1)-cy)**2/(2*sy*sy))
        img[y0:y1,x0:x1]+=D[k]*np.outer(gy,gx)
    return 200-img
def noisy(img,seed):
    r=np.random.default_rng(seed)
    # 16-bit full scale: 200 grey -> 0.5 % FS of 255-ish scale; noise 0.5% of 255 = 1.3 grey
    out=(img*200+r.normal(0,0.005*65535,img.shape))
    return np.clip(out,0,65535).astype(np.uint16)
ref=render(X,Y,sig,sig)
tifffile.imwrite(os.path.join(out, 'ref.tif'),noisy(ref,2))
tifffile.imwrite(os.path.join(out, 'trans.tif'),noisy(render(X+64.3,Y+0.4,sig,sig),3))
c,s=math.cos(math.radians(0.5)),math.sin(math.radians(0.5))
cx,cy=W/2,H/2
dx=1.01*(X-cx); dy=Y-cy
tifffile.imwrite(os.path.join(out, 'stretchrot.tif'),noisy(render(cx+c*dx-s*dy, cy+s*dx+c*dy, sig*1.01, sig),4))
print('ok')
