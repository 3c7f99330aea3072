#!/usr/bin/env python3
"""Write a kinegen CSV log as a ROS 2 bag (rosbag2 directory, MCAP storage).

The messages are serialised by `rosbags`' own ROS 2 type store, independently of
kinegen's decoder, so a bag read back by kinegen checks its message layouts
against ROS 2's. Test tooling only (pip: verify/bags/requirements.txt).

  csv_to_bag.py LOG.csv OUT_DIR --joints enc_r,enc_l|none [--pose posestamped|odometry|tf|none]
                [--cmd-vel V,OMEGA [--cmd-vel-type twist|stamped]]
                [--imu gyro_z|none] [--frame BASE] [--swap-stamps TOPIC:K] [--extra-topic]
                [--observations OBS.csv [--observation-form array|point]]

Range-bearing observations (`t,id,range,bearing`) go on `/landmarks` in a
user's own message type, as a robot would publish them, registered from its
`.msg` text: `array` writes one `test_msgs/msg/LandmarkArray` (header, then
`Landmark[] landmarks` of `string id, float64 range, float64 bearing`) per
instant; `point` writes one `test_msgs/msg/Sighting` (header, `string id`,
`geometry_msgs/Point position` in the robot frame) per observation.

`--cmd-vel` writes two CSV columns as a velocity-commanded robot's commands
on `/cmd_vel` (`linear.x`, `angular.z`): `geometry_msgs/msg/Twist`, which has
no stamp (its receive time is the log's t), or `TwistStamped`.

Header stamps are the log's t plus an epoch; receive times lag them by a few
milliseconds, and the topics are written interleaved by receive time.
"""
import argparse
import csv
import math
import random

import numpy as np
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

EPOCH = 1_700_000_000


def stamp_of(ts, t):
    Time = ts.types['builtin_interfaces/msg/Time']
    ns = int(round((EPOCH + t) * 1e9))
    return Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument('log')
    ap.add_argument('out')
    ap.add_argument('--joints', required=True, help='CSV columns written as JointState joints (same names)')
    ap.add_argument('--pose', default='posestamped', choices=['posestamped', 'odometry', 'tf', 'none'])
    ap.add_argument('--pose-columns', default='gt_x,gt_y,gt_theta')
    ap.add_argument('--frame', default='base_link', help="the robot's frame: child of the TF and Odometry poses")
    ap.add_argument('--imu', default='gyro_z', help="CSV column of the yaw rate, or 'none'")
    ap.add_argument('--swap-stamps', default=None, help='TOPIC:K swaps the header stamps of messages K and K+1')
    ap.add_argument('--extra-topic', action='store_true', help='also write a second JointState topic')
    ap.add_argument('--observations', default=None, help='range-bearing observations t,id,range,bearing')
    ap.add_argument('--observation-form', default='array', choices=['array', 'point'])
    ap.add_argument('--cmd-vel', default=None, help='V,OMEGA: CSV columns written as /cmd_vel linear.x, angular.z')
    ap.add_argument('--cmd-vel-type', default='twist', choices=['twist', 'stamped'])
    a = ap.parse_args()

    ts = get_typestore(Stores.ROS2_HUMBLE)
    user = {}
    user.update(get_types_from_msg('string id\nfloat64 range\nfloat64 bearing\n', 'test_msgs/msg/Landmark'))
    user.update(get_types_from_msg('std_msgs/Header header\ntest_msgs/Landmark[] landmarks\n',
                                   'test_msgs/msg/LandmarkArray'))
    user.update(get_types_from_msg('std_msgs/Header header\nstring id\ngeometry_msgs/Point position\n',
                                   'test_msgs/msg/Sighting'))
    ts.register(user)
    T = ts.types
    Header = T['std_msgs/msg/Header']
    rows = list(csv.DictReader(open(a.log)))
    joints = [] if a.joints == 'none' else a.joints.split(',')
    px, py, pth = a.pose_columns.split(',')
    rng = random.Random(1)
    empty = np.array([], dtype=np.float64)
    msgs = []  # (receive ns, topic, msgtype, message)
    for k, r in enumerate(rows):
        t = float(r['t'])
        hdr = Header(stamp=stamp_of(ts, t), frame_id='base_link')
        recv = lambda: int(round((EPOCH + t) * 1e9)) + rng.randint(1_000_000, 5_000_000)
        if joints:
            msgs.append((recv(), '/joint_states', 'sensor_msgs/msg/JointState', T['sensor_msgs/msg/JointState'](
                header=hdr, name=joints, position=np.array([float(r[j]) for j in joints]),
                velocity=empty, effort=empty)))
        if a.cmd_vel:
            v, w = a.cmd_vel.split(',')
            v3 = T['geometry_msgs/msg/Vector3']
            tw = T['geometry_msgs/msg/Twist'](linear=v3(x=float(r[v]), y=0.0, z=0.0),
                                              angular=v3(x=0.0, y=0.0, z=float(r[w])))
            if a.cmd_vel_type == 'twist':
                # no stamp: the receive time is the command's time
                msgs.append((int(round((EPOCH + t) * 1e9)), '/cmd_vel', 'geometry_msgs/msg/Twist', tw))
            else:
                msgs.append((recv(), '/cmd_vel', 'geometry_msgs/msg/TwistStamped',
                             T['geometry_msgs/msg/TwistStamped'](header=hdr, twist=tw)))
        if a.extra_topic:
            msgs.append((recv(), '/other/joint_states', 'sensor_msgs/msg/JointState', T['sensor_msgs/msg/JointState'](
                header=hdr, name=joints, position=np.array([0.0 for _ in joints]), velocity=empty, effort=empty)))
        if a.pose != 'none':
            x, y, th = float(r[px]), float(r[py]), float(r[pth])
            q = T['geometry_msgs/msg/Quaternion'](x=0.0, y=0.0, z=math.sin(th / 2), w=math.cos(th / 2))
            p = T['geometry_msgs/msg/Point'](x=x, y=y, z=0.0)
            pose = T['geometry_msgs/msg/Pose'](position=p, orientation=q)
            mhdr = Header(stamp=stamp_of(ts, t), frame_id='map')
            if a.pose == 'posestamped':
                msgs.append((recv(), '/mocap/pose', 'geometry_msgs/msg/PoseStamped',
                             T['geometry_msgs/msg/PoseStamped'](header=mhdr, pose=pose)))
            elif a.pose == 'odometry':
                cov = np.zeros(36)
                tw = T['geometry_msgs/msg/Twist'](linear=T['geometry_msgs/msg/Vector3'](x=0.0, y=0.0, z=0.0),
                                                  angular=T['geometry_msgs/msg/Vector3'](x=0.0, y=0.0, z=0.0))
                msgs.append((recv(), '/mocap/odom', 'nav_msgs/msg/Odometry', T['nav_msgs/msg/Odometry'](
                    header=mhdr, child_frame_id=a.frame,
                    pose=T['geometry_msgs/msg/PoseWithCovariance'](pose=pose, covariance=cov),
                    twist=T['geometry_msgs/msg/TwistWithCovariance'](twist=tw, covariance=cov))))
            else:
                tr = lambda child, pos: T['geometry_msgs/msg/TransformStamped'](
                    header=mhdr, child_frame_id=child,
                    transform=T['geometry_msgs/msg/Transform'](
                        translation=T['geometry_msgs/msg/Vector3'](x=pos.x, y=pos.y, z=0.0), rotation=q))
                msgs.append((recv(), '/tf', 'tf2_msgs/msg/TFMessage', T['tf2_msgs/msg/TFMessage'](
                    transforms=[tr('odom', T['geometry_msgs/msg/Point'](x=0.0, y=0.0, z=0.0)), tr(a.frame, p)])))
        if a.imu != 'none':
            v3 = T['geometry_msgs/msg/Vector3']
            msgs.append((recv(), '/imu/data', 'sensor_msgs/msg/Imu', T['sensor_msgs/msg/Imu'](
                header=Header(stamp=stamp_of(ts, t), frame_id='imu_link'),
                orientation=T['geometry_msgs/msg/Quaternion'](x=0.0, y=0.0, z=0.0, w=1.0),
                orientation_covariance=np.full(9, -1.0),
                angular_velocity=v3(x=0.0, y=0.0, z=float(r[a.imu])),
                angular_velocity_covariance=np.zeros(9),
                linear_acceleration=v3(x=0.0, y=0.0, z=9.81),
                linear_acceleration_covariance=np.zeros(9))))
    if a.observations:
        obs = list(csv.DictReader(open(a.observations)))
        by_t = {}
        for o in obs:
            by_t.setdefault(o['t'], []).append(o)
        for t_text, group in by_t.items():
            t = float(t_text)
            hdr = Header(stamp=stamp_of(ts, t), frame_id='base_link')
            recv = int(round((EPOCH + t) * 1e9)) + rng.randint(1_000_000, 5_000_000)
            if a.observation_form == 'array':
                marks = [T['test_msgs/msg/Landmark'](id=o['id'], range=float(o['range']), bearing=float(o['bearing']))
                         for o in group]
                msgs.append((recv, '/landmarks', 'test_msgs/msg/LandmarkArray',
                             T['test_msgs/msg/LandmarkArray'](header=hdr, landmarks=marks)))
            else:
                for o in group:
                    r, b = float(o['range']), float(o['bearing'])
                    p = T['geometry_msgs/msg/Point'](x=r * math.cos(b), y=r * math.sin(b), z=0.0)
                    msgs.append((recv, '/landmarks', 'test_msgs/msg/Sighting',
                                 T['test_msgs/msg/Sighting'](header=hdr, id=o['id'], position=p)))
    if a.swap_stamps:
        topic, k = a.swap_stamps.rsplit(':', 1)
        k = int(k)
        of_topic = [m for m in msgs if m[1] == topic]
        h1, h2 = of_topic[k][3].header, of_topic[k + 1][3].header
        h1.stamp, h2.stamp = h2.stamp, h1.stamp
    msgs.sort(key=lambda m: m[0])
    with Writer(a.out, version=8, storage_plugin=StoragePlugin.MCAP) as w:
        conns = {}
        for recv_ns, topic, msgtype, msg in msgs:
            if topic not in conns:
                conns[topic] = w.add_connection(topic, msgtype, typestore=ts)
            w.write(conns[topic], recv_ns, ts.serialize_cdr(msg, msgtype))


if __name__ == '__main__':
    main()
