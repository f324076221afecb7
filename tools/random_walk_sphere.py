import numpy as np
rng=np.random.default_rng(1)
def exit_fraction(sa, ss, R=10.0, N=20000, maxsteps=20000):
    st=sa+ss; alb=ss/st
    # start at the surface point (0,0,R), direction into the sphere, cosine weighted about -z
    u1,u2=rng.random(N),rng.random(N)
    r=np.sqrt(u1); phi=2*np.pi*u2
    d=np.stack([r*np.cos(phi), r*np.sin(phi), -np.sqrt(1-u1)],1)
    x=np.tile([0,0,R-1e-9],(N,1)).astype(float)
    alive=np.ones(N,bool); out=0.0
    for step in range(maxsteps):
        idx=np.nonzero(alive)[0]
        if len(idx)==0: break
        xi,di=x[idx],d[idx]
        t=-np.log(rng.random(len(idx)))/st
        # distance to sphere boundary along d: solve |x+s d|=R
        b=np.sum(xi*di,1); c=np.sum(xi*xi,1)-R*R
        s=-b+np.sqrt(np.maximum(b*b-c,0))
        exits=t>=s
        out+=exits.sum()
        alive[idx[exits]]=False
        stay=idx[~exits]
        x[stay]=xi[~exits]+t[~exits,None]*di[~exits]
        # absorption
        surv=rng.random(len(stay))<alb
        alive[stay[~surv]]=False
        st2=stay[surv]
        v=rng.normal(size=(len(st2),3)); v/=np.linalg.norm(v,axis=1)[:,None]
        d[st2]=v
    return out/N
sa=np.array([0.032,0.17,0.48]); ss=np.array([0.74,0.88,1.01])
print('skin1 sphere R=10', [round(exit_fraction(sa[c],ss[c]),4) for c in range(3)])
print('skin1 slab (R=1e4)', [round(exit_fraction(sa[c],ss[c],R=1e4),4) for c in range(3)])
