--[[
  returnlink.lua: return to link for an unmodified ArduPilot Rover (4.5 or later), no extra hardware.

  What it does
    While the rover is armed it lays breadcrumbs from the EKF's position (ahrs:get_relative_position_NED_origin),
    each tagged with the state of the owner's link: link-good when the ground station's HEARTBEAT was heard within
    RLNK_GOOD_S (gcs:last_seen, the same clock the firmware's own GCS failsafe reads), and the telemetry radio's
    RSSI when the vehicle-side radio reports RADIO_STATUS on a MAVLink port (a SiK radio does). Crumbs are spaced
    RLNK_SPACING apart and simplified within RLNK_TOL (a point is dropped only while every position driven since
    the point kept before it stays within RLNK_TOL of the straight line); link transitions are never simplified.

    When the owner has been silent for RLNK_TIMEOUT (and the rover is armed in one of the modes listed in
    DRIVEN_MODES below), it switches to GUIDED and drives back along its crumbs toward the nearest place the link
    was good before this loss, and on past it along the trail while the link is still not back (a place that was
    good once may not be now). It steers itself (turn rate and speed targets, pure pursuit of a point just ahead on
    the trail): backward when the trail lies behind, so a rover in a corridor never swings round, at the speed it
    was driven lately (or RLNK_SPEED); the firmware stops it 3 s after the last target should the script die.
    From the first heartbeat heard again it slows to RLNK_APPR_SPD; once a run of heartbeats (at least two, no more
    than RLNK_GOOD_S apart) has lasted RLNK_REGAIN_S it brakes (a zero speed target in GUIDED, because HOLD lets a
    rover roll) until the rover stands, then switches to HOLD. It also stops (brake, then HOLD) at RLNK_MAX_DISP
    from where the return began, after RLNK_MAX_TIME, when the rover makes no progress for RLNK_STUCK_S, or at
    the trail's start.
    A mode change by anyone else (the pilot's switch, the ground station, the firmware's own failsafe) ends the
    return at once, as does a GUIDED location target (it sets none): it never fights the pilot. Every start and
    stop, with its reason, is a STATUSTEXT beginning "RLNK:".

  Memory
    A crumb is four numbers in four arrays (north, east, time, the link tag and RSSI packed in one), 16 bytes
    each in Lua 5.3; arrays grow by doubling, so RLNK_MAX_PTS crumbs take at most 2 x 4 x 16 = 128 bytes each:
    300 crumbs (the default) at most 38 KB, 1000 (the most allowed) at most 125 KB of a 256 KB SCR_HEAP_SIZE.
    When the trail is full, every other crumb of its older half goes (the tolerance grows for the oldest part
    first; link transitions stay); it never stops recording.

  RADIO_STATUS
    Read through mavlink:register_rx_msgid where the firmware has that binding (4.5 and later). The RSSI is kept
    with each crumb for the log and the ground station; with RLNK_MIN_RSSI above 0 a crumb is link-good only if the
    radio's RSSI (0-254, SiK units) was at least that. A firmware without the binding, or no radio reporting, is
    said once at start; the heartbeat alone then decides.

  Install
    1. Copy this file to APM/scripts/ on the flight controller's SD card.
    2. Set SCR_ENABLE 1 and reboot; the RLNK_ parameters appear (refresh the parameter list).
    3. Keep the firmware's own GCS failsafe on as the backstop: FS_GCS_ENABLE 1, FS_ACTION 2 (Hold) or 4
       (SmartRTL, else Hold), and FS_GCS_TIMEOUT longer than RLNK_TIMEOUT plus the time a return needs (e.g. 30 s
       for RLNK_TIMEOUT 3). The script acts first; the firmware's failsafe fires only if the owner is still silent
       FS_GCS_TIMEOUT + FS_TIMEOUT after the last heartbeat, which is also what happens if the script dies.
    4. Check the ground station shows "RLNK: ready" after boot.

  Parameters (ArduPilot style: name, range, units, default)
    RLNK_ENABLE    0 1          -      1     0 disables the script (it keeps running, doing nothing)
    RLNK_TIMEOUT   0.5 120      s      3     owner silent this long: the return starts
    RLNK_REGAIN_S  0 10         s      1     owner heard this long again: the return stops
    RLNK_GOOD_S    0.1 10       s      1.5   a crumb is link-good if the owner was heard within this
    RLNK_MAX_DISP  1 10000      m      50    the return never ends farther than this from where it began
    RLNK_MAX_TIME  0 3600       s      300   the return gives up after this (0: no limit)
    RLNK_SPEED     0 5          m/s    0     return speed (0: leave the speed the rover was driven at)
    RLNK_APPR_SPD  0 5          m/s    0.5   speed once the owner is heard again, until the stop (0: no change)
    RLNK_SPACING   0.05 10      m      0.5   minimum distance between crumbs
    RLNK_TOL       0.01 5       m      0.25  simplification tolerance
    RLNK_MAX_PTS   50 1000      -      300   memory bound of the trail, in crumbs
    RLNK_ARRIVE_R  0.1 10       m      1     a crumb or the displacement limit counts as reached within this
    RLNK_STUCK_S   1 60         s      5     no progress along the trail for this long: the return ends (STUCK)
    RLNK_MIN_RSSI  0 254        -      0     RADIO_STATUS rssi below this makes a crumb link-lost (0: not used)
--]]

local PARAM_TABLE_KEY = 74 -- must be unique among the scripts on one flight controller
local PARAM_PREFIX = "RLNK_"
local TAG = "RLNK: "

local MODE_HOLD = 4
local MODE_GUIDED = 15
-- the modes it protects: a loss in one of these starts a return (MANUAL, ACRO, STEERING, GUIDED);
-- never from HOLD, LOITER, AUTO, RTL or SMART_RTL, where the firmware is already doing what it was told
local DRIVEN_MODES = { [0] = true, [1] = true, [3] = true, [15] = true }

local PERIOD_MS = 100 -- 10 Hz: crumbs, the link and the return are all updated at this rate
local REST_SPEED = 0.1 -- m/s: the rover stands
local BRAKE_LIMIT_MS = 4000 -- the brake gives way to HOLD after this even if the rover is still creeping
local CARROT_MIN_M = 1.5 -- the point steered at lies this far ahead along the trail ...
local CARROT_S = 1.5 -- ... or this many seconds of travel, if that is farther
local TURN_GAIN = 2.0 -- deg/s of turn rate per degree of heading error
local TURN_MAX_DEGS = 90 -- the turn rate asked for at most
local PIVOT_RAD = 0.6 -- heading error beyond which the rover turns on the spot before it drives
local FLIP_RAD = 2.1 -- heading error (about 120 deg) beyond which it changes between forward and reverse
local MIN_SPEED = 0.3 -- m/s: the return is never slower than this (before the approach)
local CRUISE_MOVING = 0.2 -- m/s: the outbound speed is learned only while the rover moves at least this fast
local CRUISE_DECAY = 0.005 -- m/s per period (0.05 m/s per s) the learned outbound speed falls when driven slower
local PROGRESS_M = 0.3 -- remaining trail must shrink by this within RLNK_STUCK_S ...
local TURNING_RADS = 0.2 -- ... or the rover turn on the spot at least this fast (rad/s)
local WINDOW = 32 -- positions remembered since the last kept crumb, for the simplification's check
local MSG_RADIO_STATUS = 109

-- ----- parameters -------------------------------------------------------------------------------------------
assert(param:add_table(PARAM_TABLE_KEY, PARAM_PREFIX, 14), "RLNK: could not add param table")

local function bind_add_param(name, idx, default_value)
  assert(param:add_param(PARAM_TABLE_KEY, idx, name, default_value), "RLNK: could not add " .. PARAM_PREFIX .. name)
  return Parameter(PARAM_PREFIX .. name)
end

--[[
  // @Param: RLNK_ENABLE
  // @DisplayName: Return to link enable
  // @Description: Enables the return to link script
  // @Values: 0:Disabled,1:Enabled
  // @User: Standard
--]]
local RLNK_ENABLE = bind_add_param("ENABLE", 1, 1)

--[[
  // @Param: RLNK_TIMEOUT
  // @DisplayName: Link loss timeout
  // @Description: The ground station silent (no HEARTBEAT) this long starts the return. Keep it shorter than FS_GCS_TIMEOUT so the script acts before the firmware's own failsafe
  // @Units: s
  // @Range: 0.5 120
  // @User: Standard
--]]
local RLNK_TIMEOUT = bind_add_param("TIMEOUT", 2, 3)

--[[
  // @Param: RLNK_REGAIN_S
  // @DisplayName: Link regain time
  // @Description: The ground station heard again this long (heartbeats no more than RLNK_GOOD_S apart) stops the return
  // @Units: s
  // @Range: 0 10
  // @User: Standard
--]]
local RLNK_REGAIN_S = bind_add_param("REGAIN_S", 3, 1)

--[[
  // @Param: RLNK_GOOD_S
  // @DisplayName: Link-good age
  // @Description: A crumb is link-good if the ground station was heard within this time when it was laid
  // @Units: s
  // @Range: 0.1 10
  // @User: Advanced
--]]
local RLNK_GOOD_S = bind_add_param("GOOD_S", 4, 1.5)

--[[
  // @Param: RLNK_MAX_DISP
  // @DisplayName: Maximum displacement
  // @Description: The return never ends farther than this from where it began
  // @Units: m
  // @Range: 1 10000
  // @User: Standard
--]]
local RLNK_MAX_DISP = bind_add_param("MAX_DISP", 5, 50)

--[[
  // @Param: RLNK_MAX_TIME
  // @DisplayName: Maximum return time
  // @Description: The return gives up after this time (0: no limit)
  // @Units: s
  // @Range: 0 3600
  // @User: Standard
--]]
local RLNK_MAX_TIME = bind_add_param("MAX_TIME", 6, 300)

--[[
  // @Param: RLNK_SPEED
  // @DisplayName: Return speed
  // @Description: Speed of the return (0: the speed the rover was being driven at)
  // @Units: m/s
  // @Range: 0 5
  // @User: Standard
--]]
local RLNK_SPEED = bind_add_param("SPEED", 7, 0)

--[[
  // @Param: RLNK_APPR_SPD
  // @DisplayName: Approach speed
  // @Description: Speed from the first heartbeat heard again until the stop, so the regain time and the brake end near where the link came back (0: no change)
  // @Units: m/s
  // @Range: 0 5
  // @User: Advanced
--]]
local RLNK_APPR_SPD = bind_add_param("APPR_SPD", 8, 0.5)

--[[
  // @Param: RLNK_SPACING
  // @DisplayName: Crumb spacing
  // @Description: Minimum distance between crumbs
  // @Units: m
  // @Range: 0.05 10
  // @User: Advanced
--]]
local RLNK_SPACING = bind_add_param("SPACING", 9, 0.5)

--[[
  // @Param: RLNK_TOL
  // @DisplayName: Trail tolerance
  // @Description: Simplification tolerance: every position driven stays within this of the trail kept
  // @Units: m
  // @Range: 0.01 5
  // @User: Advanced
--]]
local RLNK_TOL = bind_add_param("TOL", 10, 0.25)

--[[
  // @Param: RLNK_MAX_PTS
  // @DisplayName: Trail memory bound
  // @Description: Most crumbs kept (about 128 bytes of scripting heap each at worst); when full the older half is thinned
  // @Range: 50 1000
  // @User: Advanced
--]]
local RLNK_MAX_PTS = bind_add_param("MAX_PTS", 11, 300)

--[[
  // @Param: RLNK_ARRIVE_R
  // @DisplayName: Arrival radius
  // @Description: A crumb or the displacement limit counts as reached within this distance
  // @Units: m
  // @Range: 0.1 10
  // @User: Advanced
--]]
local RLNK_ARRIVE_R = bind_add_param("ARRIVE_R", 12, 1)

--[[
  // @Param: RLNK_STUCK_S
  // @DisplayName: Stuck time
  // @Description: No progress along the trail for this long ends the return (STUCK)
  // @Units: s
  // @Range: 1 60
  // @User: Advanced
--]]
local RLNK_STUCK_S = bind_add_param("STUCK_S", 13, 5)

--[[
  // @Param: RLNK_MIN_RSSI
  // @DisplayName: Minimum radio RSSI
  // @Description: With a telemetry radio reporting RADIO_STATUS, a crumb laid while its rssi was below this is link-lost (0: not used)
  // @Range: 0 254
  // @User: Advanced
--]]
local RLNK_MIN_RSSI = bind_add_param("MIN_RSSI", 14, 0)

-- ----- the trail ------------------------------------------------------------------------------------------------
local tn, te, tt, tg = {}, {}, {}, {} -- north, east, time (ms), tag: 2 * rssi (255: unknown), +1 if link-good
local count = 0
local window_n, window_e, window_len = {}, {}, 0 -- positions driven since the crumb before the last one
local last_n, last_e = nil, nil -- the last position spaced out (kept or simplified away)

local function seg_dist(pn, pe, an, ae, bn, be)
  local dn, de = bn - an, be - ae
  local len2 = dn * dn + de * de
  local s = 0
  if len2 > 1e-9 then
    s = math.max(0, math.min(1, ((pn - an) * dn + (pe - ae) * de) / len2))
  end
  local qn, qe = an + s * dn - pn, ae + s * de - pe
  return math.sqrt(qn * qn + qe * qe)
end

local function good_of(tag)
  return tag % 2 == 1
end

local function thin_oldest()
  -- memory full: every other crumb of the older half goes, link transitions stay
  local half = count // 2
  local keep = 0
  local on, oe, ot, og = {}, {}, {}, {}
  for i = 1, count do
    local transition = i == 1 or i == count or good_of(tg[i]) ~= good_of(tg[i - 1]) or
                       good_of(tg[i]) ~= good_of(tg[i + 1])
    if i > half or transition or i % 2 == 1 then
      keep = keep + 1
      on[keep], oe[keep], ot[keep], og[keep] = tn[i], te[i], tt[i], tg[i]
    end
  end
  tn, te, tt, tg, count = on, oe, ot, og, keep
end

local function lay(n, e, now, tag)
  -- the window holds every position since crumb count-1: the last crumb may move to here if all stay within TOL
  window_len = window_len + 1
  window_n[window_len], window_e[window_len] = n, e
  local same = count >= 2 and good_of(tg[count]) == good_of(tg[count - 1]) and good_of(tag) == good_of(tg[count])
  if same and window_len <= WINDOW then
    local an, ae = tn[count - 1], te[count - 1]
    local tol = RLNK_TOL:get()
    local fits = true
    for k = 1, window_len do
      if seg_dist(window_n[k], window_e[k], an, ae, n, e) > tol then
        fits = false
        break
      end
    end
    if fits then
      tn[count], te[count], tt[count] = n, e, now
      return
    end
  end
  if count >= RLNK_MAX_PTS:get() then
    thin_oldest()
  end
  count = count + 1
  tn[count], te[count], tt[count], tg[count] = n, e, now, tag
  window_n, window_e, window_len = { n }, { e }, 1
end

local function reset_trail()
  tn, te, tt, tg, count = {}, {}, {}, {}, 0
  window_n, window_e, window_len = {}, {}, 0
  last_n, last_e = nil, nil
end

-- ----- the owner's link -------------------------------------------------------------------------------------------
local radio_ok = false -- the firmware lets scripts read RADIO_STATUS
local rssi = 255 -- 255: unknown, as RADIO_STATUS says it
local rssi_ms = 0

local function read_radio(now)
  if not radio_ok then
    return
  end
  while true do
    local msg = mavlink:receive_chan()
    if not msg then
      break
    end
    -- mavlink_message_t as bytes: checksum(2) magic len incompat compat seq sysid compid msgid(3), then payload
    local len = string.unpack("<B", msg, 4)
    local msgid = string.unpack("<I3", msg, 10)
    if msgid == MSG_RADIO_STATUS then
      rssi = len >= 5 and string.unpack("<B", msg, 17) or 0
      rssi_ms = now
    end
  end
  if now - rssi_ms > 5000 then
    rssi = 255
  end
end

local function heard_age_s(now)
  local seen = gcs:last_seen():toint()
  if seen == 0 then
    return nil -- never heard: no owner to lose
  end
  return (now - seen) / 1000.0, seen
end

local function link_good(now)
  local age = heard_age_s(now)
  if age == nil or age > RLNK_GOOD_S:get() then
    return false
  end
  local min_rssi = RLNK_MIN_RSSI:get()
  return min_rssi <= 0 or rssi == 255 or rssi >= min_rssi
end

-- ----- the return ---------------------------------------------------------------------------------------------------
local state = "record" -- record, returning, braking
local ret = {} -- the running return: start, time, loss, progress, our target, reason to stop
local last_armed = false
local cruise = 0 -- m/s: the speed the rover was driven at lately (RLNK_SPEED 0 returns at it)

local function say(severity, text)
  gcs:send_text(severity, TAG .. text)
end

local function position()
  local p = ahrs:get_relative_position_NED_origin()
  if p == nil then
    return nil
  end
  return p:x(), p:y()
end

local function speed_now()
  local v = ahrs:get_velocity_NED()
  if v == nil then
    return 0
  end
  return math.sqrt(v:x() * v:x() + v:y() * v:y())
end

local function remaining(n, e)
  -- length of the trail still to drive from (n, e)
  if count == 0 then
    return 0
  end
  local d = math.sqrt((tn[count] - n) ^ 2 + (te[count] - e) ^ 2)
  for i = count, 2, -1 do
    d = d + math.sqrt((tn[i] - tn[i - 1]) ^ 2 + (te[i] - te[i - 1]) ^ 2)
  end
  return d
end

local function clip_to_circle(an, ae, bn, be, cn, ce, r)
  -- the point of segment a->b where it leaves the circle (c, r), a inside
  local dn, de = bn - an, be - ae
  local fn, fe = an - cn, ae - ce
  local a = dn * dn + de * de
  if a < 1e-9 then
    return an, ae
  end
  local b = 2 * (fn * dn + fe * de)
  local c = fn * fn + fe * fe - r * r
  local disc = math.max(0, b * b - 4 * a * c)
  local s = math.max(0, math.min(1, (-b + math.sqrt(disc)) / (2 * a)))
  return an + s * dn, ae + s * de
end

local function carrot(n, e)
  -- the point CARROT ahead along the trail from (n, e), within the displacement circle; true when it is the end
  local ahead = math.max(CARROT_MIN_M, CARROT_S * speed_now())
  local r = RLNK_MAX_DISP:get()
  local an, ae = n, e
  for i = count, 1, -1 do
    local bn, be = tn[i], te[i]
    if (bn - ret.n0) ^ 2 + (be - ret.e0) ^ 2 > r * r then
      local cn, ce = clip_to_circle(an, ae, bn, be, ret.n0, ret.e0, r)
      return cn, ce, "max displacement"
    end
    local leg = math.sqrt((bn - an) ^ 2 + (be - ae) ^ 2)
    if leg >= ahead then
      local s = ahead / leg
      return an + s * (bn - an), ae + s * (be - ae), nil
    end
    ahead = ahead - leg
    an, ae = bn, be
  end
  return an, ae, "trail start"
end

local function pass_crumbs(n, e)
  -- crumbs reached, or already behind the rover on its way, are consumed: the trail ends where the rover is
  local arrive = RLNK_ARRIVE_R:get()
  while count >= 1 do
    local d = math.sqrt((tn[count] - n) ^ 2 + (te[count] - e) ^ 2)
    local passed = false
    if count >= 2 then
      local near = seg_dist(n, e, tn[count], te[count], tn[count - 1], te[count - 1])
      local to_next = math.sqrt((tn[count - 1] - n) ^ 2 + (te[count - 1] - e) ^ 2)
      local leg = math.sqrt((tn[count - 1] - tn[count]) ^ 2 + (te[count - 1] - te[count]) ^ 2)
      passed = near < arrive and to_next < leg
    end
    if d < arrive or passed then
      tn[count], te[count], tt[count], tg[count] = nil, nil, nil, nil
      count = count - 1
    else
      break
    end
  end
  window_n, window_e, window_len = {}, {}, 0
end


local function elapsed_s(now)
  return (now - ret.t0) / 1000.0
end

local function finish(severity, why, now)
  local n, e = position()
  local back = n and math.sqrt((n - ret.n0) ^ 2 + (e - ret.e0) ^ 2) or 0
  say(severity, string.format("stopped: %s, %.0f s, %.1f m", why, elapsed_s(now), back))
end

local function start_braking(why, now)
  ret.why = why
  ret.brake_ms = now
  state = "braking"
  vehicle:set_desired_turn_rate_and_speed(0, 0)
end

local function pilot_took_over(now)
  -- anyone else's mode or target ends the return at once
  local mode = vehicle:get_mode()
  if mode ~= MODE_GUIDED then
    say(4, string.format("ended: mode %d reason %d, %.1f s", mode, vehicle:get_control_mode_reason(),
                         elapsed_s(now)))
    return true
  end
  -- it drives with turn rates and speeds, which leave no location target: one showing up is someone else's
  if vehicle:get_target_location() ~= nil then
    say(4, string.format("ended: pilot's target, %.1f s", elapsed_s(now)))
    return true
  end
  return false
end

local function start_return(now, n, e)
  local age, seen = heard_age_s(now)
  -- the target: the last crumb laid while the owner was still heard, before this loss
  local target_i = 0
  for i = count, 1, -1 do
    if good_of(tg[i]) and tt[i] <= seen then
      target_i = i
      break
    end
  end
  if count == 0 then
    say(4, string.format("no return: silent %.1f s, no trail", age))
    ret = { skipped = seen }
    return
  end
  if not vehicle:set_mode(MODE_GUIDED) then
    say(4, string.format("no return: silent %.1f s, no GUIDED", age))
    ret = { skipped = seen }
    return
  end
  local back = 0
  if target_i > 0 then
    local an, ae = n, e
    for i = count, target_i, -1 do
      back = back + math.sqrt((tn[i] - an) ^ 2 + (te[i] - ae) ^ 2)
      an, ae = tn[i], te[i]
    end
  end
  local speed = RLNK_SPEED:get()
  ret = { t0 = now, n0 = n, e0 = e, seen = seen, best = remaining(n, e), best_ms = now, contact = nil,
          last_heard = seen, beats = 0, dir = nil, speed = speed > 0 and speed or math.max(MIN_SPEED, cruise) }
  state = "returning"
  if target_i > 0 then
    say(4, string.format("return: silent %.1f s, good %.1f m back", age, back))
  else
    say(4, string.format("return: silent %.1f s, no good crumb", age))
  end
end

local function regained(now)
  -- owner heard again since the loss: a run of heartbeats no more than RLNK_GOOD_S apart, the last within
  -- RLNK_GOOD_S, lasting RLNK_REGAIN_S and holding at least two heartbeats (one stray heartbeat at the fringe,
  -- followed by silence, is not a link: measured, open world, a return stopped 0.7 m into it on one such)
  local seen = gcs:last_seen():toint()
  local good_ms = RLNK_GOOD_S:get() * 1000
  if seen ~= ret.seen and seen ~= ret.last_heard then
    if ret.contact == nil or seen - ret.last_heard > good_ms then
      ret.contact, ret.beats = seen, 1
    else
      ret.beats = ret.beats + 1
    end
    ret.last_heard = seen
  end
  if ret.contact ~= nil and now - ret.last_heard > good_ms then
    ret.contact = nil -- the run broke: back to the return's own speed (drive)
  end
  if ret.contact == nil then
    return false
  end
  local regain_ms = RLNK_REGAIN_S:get() * 1000
  return (ret.beats >= 2 or regain_ms <= 0) and now - ret.contact >= regain_ms
end

-- ----- the states: each runs once a period ------------------------------------------------------------------------
local function record(now)
  local n, e = position()
  if n == nil then
    return
  end
  local v = speed_now()
  if v > CRUISE_MOVING then
    -- the speed driven lately: follows it up at once, down slowly, so the slowing after the owner's last
    -- command (before the loss is noticed) does not set the return's pace
    cruise = math.max(v, cruise - CRUISE_DECAY)
  end
  local spacing = RLNK_SPACING:get()
  if last_n == nil or (n - last_n) ^ 2 + (e - last_e) ^ 2 >= spacing * spacing then
    last_n, last_e = n, e
    lay(n, e, now, rssi * 2 + (link_good(now) and 1 or 0))
  end
  local age, seen = heard_age_s(now)
  if age == nil or age < RLNK_TIMEOUT:get() or ret.skipped == seen then
    return
  end
  if RLNK_ENABLE:get() < 1 or not DRIVEN_MODES[vehicle:get_mode()] then
    return
  end
  start_return(now, n, e)
end

local function give_way(now)
  -- someone else has the rover: no new return for this silence (the next loss, after a heartbeat, starts one)
  local _, seen = heard_age_s(now)
  ret = { skipped = seen }
  state = "record"
end

-- ArduPilot 4.7 renamed ahrs:get_yaw (kept with a warning) to ahrs:get_yaw_rad; older ones have only the first
local found, yaw_rad_binding = pcall(function() return ahrs.get_yaw_rad end)
local has_yaw_rad = found and yaw_rad_binding ~= nil

local function yaw_rad()
  if has_yaw_rad then
    return ahrs:get_yaw_rad()
  end
  return ahrs:get_yaw()
end

local function wrap_pi(a)
  return (a + math.pi) % (2 * math.pi) - math.pi
end

local function drive(n, e, cn, ce, now)
  -- pure pursuit of the point (cn, ce) ahead on the trail with a turn rate and a speed in GUIDED: backward when the
  -- trail lies behind the rover (a return never swings a U-turn in a corridor), turning on the spot when the
  -- heading is far off. The firmware stops the rover by itself 3 s after the last such target (a dead man).
  local bearing = math.atan(ce - e, cn - n)
  local yaw = yaw_rad()
  if ret.dir == nil then
    ret.dir = math.abs(wrap_pi(bearing - yaw)) > math.pi / 2 and -1 or 1
  end
  local err = wrap_pi(bearing - yaw - (ret.dir < 0 and math.pi or 0))
  if math.abs(err) > FLIP_RAD then
    ret.dir = -ret.dir
    err = wrap_pi(err + math.pi)
  end
  local rate = math.max(-TURN_MAX_DEGS, math.min(TURN_MAX_DEGS, TURN_GAIN * math.deg(err)))
  local v = ret.speed
  if ret.contact ~= nil and RLNK_APPR_SPD:get() > 0 then -- the owner is being heard again: approach
    v = math.min(v, RLNK_APPR_SPD:get())
  end
  if math.abs(err) > PIVOT_RAD then
    v = 0
  else
    v = v * math.cos(err)
  end
  vehicle:set_desired_turn_rate_and_speed(rate, ret.dir * v)
end

local function returning(now)
  if pilot_took_over(now) then
    give_way(now)
    return
  end
  local n, e = position()
  if n == nil then
    start_braking("no position", now)
    return
  end
  if regained(now) then
    start_braking("link regained", now)
    return
  end
  local max_time = RLNK_MAX_TIME:get()
  if max_time > 0 and elapsed_s(now) > max_time then
    start_braking("time limit", now)
    return
  end
  pass_crumbs(n, e)
  local cn, ce, final = carrot(n, e)
  if final ~= nil and math.sqrt((cn - n) ^ 2 + (ce - e) ^ 2) < RLNK_ARRIVE_R:get() then
    start_braking(final, now)
    return
  end
  local left = remaining(n, e)
  local gyro = ahrs:get_gyro()
  local turning = gyro ~= nil and math.abs(gyro:z()) > TURNING_RADS
  if left < ret.best - PROGRESS_M or turning then -- a pivot toward the trail is progress too
    ret.best, ret.best_ms = left, now
  elseif now - ret.best_ms > RLNK_STUCK_S:get() * 1000 then
    start_braking("stuck", now)
    return
  end
  drive(n, e, cn, ce, now)
end

local function braking(now)
  if pilot_took_over(now) then
    give_way(now)
    return
  end
  if speed_now() > REST_SPEED and now - ret.brake_ms < BRAKE_LIMIT_MS then
    vehicle:set_desired_turn_rate_and_speed(0, 0)
    return
  end
  vehicle:set_mode(MODE_HOLD)
  finish(ret.why == "link regained" and 6 or 4, ret.why, now)
  give_way(now) -- this silence has had its return
  last_n, last_e = nil, nil
end

local STATES = { record = record, returning = returning, braking = braking }

function update()
  local now = millis():toint()
  read_radio(now)
  local armed = arming:is_armed()
  if armed and not last_armed then
    reset_trail()
  end
  last_armed = armed
  if not armed then
    if state ~= "record" then
      say(4, "ended: disarmed")
      give_way(now)
    end
    return update, PERIOD_MS
  end
  STATES[state](now)
  return update, PERIOD_MS
end

-- ----- start ----------------------------------------------------------------------------------------------------------
if mavlink ~= nil and mavlink.register_rx_msgid ~= nil then
  radio_ok = pcall(function()
    mavlink:init(1, 4)
    mavlink:register_rx_msgid(MSG_RADIO_STATUS)
  end)
end
say(6, string.format("ready, timeout %.1f s, %s", RLNK_TIMEOUT:get(),
                     radio_ok and "RADIO_STATUS read" or "heartbeat only"))

return update, 1000
