#!/usr/bin/python3
# Relative rotation error over 1 s (issue 16's RRE): for every 5th pose of an estimated trajectory
# and the pose of the same trajectory 1 s later, the angle between the estimate's relative rotation
# and the ground truth's (slerp-interpolated at both stamps); next to it the same for the measured
# gyro (imu.txt, ECD order t ax ay az gx gy gz, body = IMU frame) integrated over the same interval
# (trapezoid on linearly interpolated rates, no bias removed). Prints "rms_est_deg rms_gyro_deg n".
#   bench/rre_1s.py SEQ TRAJ.tum      (SEQ: an `evio simulate` folder with groundtruth.txt, imu.txt)
import sys, numpy as np, bisect
def q2R(x,y,z,w):
    return np.array([[1-2*(y*y+z*z),2*(x*y-z*w),2*(x*z+y*w)],[2*(x*y+z*w),1-2*(x*x+z*z),2*(y*z-x*w)],[2*(x*z-y*w),2*(y*z+x*w),1-2*(x*x+y*y)]])
def load(p):
    a=np.loadtxt(p,comments='#'); return a[:,0],[q2R(*r[4:8]) for r in a]
def ang(R): return np.degrees(np.arccos(np.clip((np.trace(R)-1)/2,-1,1)))
def expm(w):
    th=np.linalg.norm(w)
    if th<1e-12: return np.eye(3)
    k=w/th; K=np.array([[0,-k[2],k[1]],[k[2],0,-k[0]],[-k[1],k[0],0]])
    return np.eye(3)+np.sin(th)*K+(1-np.cos(th))*K@K
if len(sys.argv) != 3:
    sys.exit('usage: bench/rre_1s.py SEQ TRAJ.tum')
seq,traj=sys.argv[1],sys.argv[2]
tg,Rg=load(seq+'/groundtruth.txt'); te,Re=load(traj)
imu=np.loadtxt(seq+'/imu.txt',comments='#')
def logm(R):
    th=np.arccos(np.clip((np.trace(R)-1)/2,-1,1))
    if th<1e-12: return np.zeros(3)
    return th/(2*np.sin(th))*np.array([R[2,1]-R[1,2],R[0,2]-R[2,0],R[1,0]-R[0,1]])
def gt_at(t):
    i=bisect.bisect_right(tg,t)
    if i<=0 or i>=len(tg): return None
    a=(t-tg[i-1])/(tg[i]-tg[i-1])
    return Rg[i-1]@expm(a*logm(Rg[i-1].T@Rg[i]))
def w_at(t):
    k=bisect.bisect_right(imu[:,0],t)-1; k=min(max(k,0),len(imu)-2)
    a=(t-imu[k,0])/(imu[k+1,0]-imu[k,0]); return (1-a)*imu[k,4:7]+a*imu[k+1,4:7]
def gyro(t0,t1):
    ts=[t0]+[x for x in imu[:,0] if t0<x<t1]+[t1]
    R=np.eye(3)
    for a,b in zip(ts[:-1],ts[1:]):
        R=R@expm(0.5*(w_at(a)+w_at(b))*(b-a))
    return R
ee=[];eg=[]
for i in range(0,len(te),5):
    t0=te[i]; j=bisect.bisect_left(te,t0+1.0)
    if j>=len(te) or abs(te[j]-t0-1.0)>0.02: continue
    G0=gt_at(t0); G1=gt_at(te[j])
    if G0 is None or G1 is None: continue
    rel_gt=G0.T@G1
    ee.append(ang(rel_gt.T@(Re[i].T@Re[j]))); eg.append(ang(rel_gt.T@gyro(t0,te[j])))
if not ee:
    sys.exit('rre_1s: no pose pair 1 s apart with ground truth')
print(f"{np.sqrt(np.mean(np.square(ee))):.3f} {np.sqrt(np.mean(np.square(eg))):.3f} {len(ee)}")
