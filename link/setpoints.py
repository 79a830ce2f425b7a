"""SET_POSITION_TARGET_LOCAL_NED type masks for teleoperation by velocity, from the dialect's bits.

A ground rover is driven by velocity (north/east or body forward) and, optionally, a yaw rate: everything else in
the target is marked "ignore". The station builds its teleop stream from these masks and the vehicle reads the
stream by the same bits, so the two cannot disagree about which fields carry the command.
"""

from __future__ import annotations

from link import dialect

mav = dialect.load()

IGNORE_POSITION = (mav.POSITION_TARGET_TYPEMASK_X_IGNORE | mav.POSITION_TARGET_TYPEMASK_Y_IGNORE
                   | mav.POSITION_TARGET_TYPEMASK_Z_IGNORE)
IGNORE_VELOCITY = (mav.POSITION_TARGET_TYPEMASK_VX_IGNORE | mav.POSITION_TARGET_TYPEMASK_VY_IGNORE
                   | mav.POSITION_TARGET_TYPEMASK_VZ_IGNORE)
IGNORE_ACCELERATION = (mav.POSITION_TARGET_TYPEMASK_AX_IGNORE | mav.POSITION_TARGET_TYPEMASK_AY_IGNORE
                       | mav.POSITION_TARGET_TYPEMASK_AZ_IGNORE)
IGNORE_YAW_RATE = mav.POSITION_TARGET_TYPEMASK_YAW_RATE_IGNORE

# velocity and yaw rate used: position, acceleration and yaw ignored
VELOCITY_YAW_RATE = IGNORE_POSITION | IGNORE_ACCELERATION | mav.POSITION_TARGET_TYPEMASK_YAW_IGNORE
# velocity alone (the vehicle steers towards it)
VELOCITY = VELOCITY_YAW_RATE | IGNORE_YAW_RATE
