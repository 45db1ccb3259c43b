"""Talk to a (simulated) Dynamixel bus with ROBOTIS's own Python SDK (`dynamixel-sdk`).

Usage: python3 dxl_robotis_sdk_check.py PORT
Exits 0 and prints "SDK-CHECK OK" when every step behaves as on a real XL430 pair
(driver ID 1, torque-off follower ID 2); exits 1 with the failing step otherwise.
Run by tests/dxl_robotis_sdk.rs.
"""
import sys
import time

import dynamixel_sdk.port_handler
from dynamixel_sdk import (COMM_SUCCESS, GroupBulkRead, GroupSyncRead, GroupSyncWrite,
                           PacketHandler, PortHandler)

# The SDK waits 2 × LATENCY_TIMER + 2 ms (+ transfer time) for a reply: 34 ms by default,
# matched to a USB adapter's 16 ms latency timer. CI machines run many tests at once, so
# allow for a busy scheduler (the simulator answers in about 1 ms when it gets the CPU).
dynamixel_sdk.port_handler.LATENCY_TIMER = 250


def fail(step, detail):
    print(f"SDK-CHECK FAIL {step}: {detail}")
    sys.exit(1)


def ok(step, res, err, ph):
    if res != COMM_SUCCESS:
        fail(step, ph.getTxRxResult(res))
    if err != 0:
        fail(step, ph.getRxPacketError(err))


def main():
    port = PortHandler(sys.argv[1])
    ph = PacketHandler(2.0)
    if not port.openPort():
        fail("open", sys.argv[1])
    if not port.setBaudRate(57600):
        fail("baud", "57600 refused")

    model, res, err = ph.ping(port, 1)
    ok("ping 1", res, err, ph)
    if model != 1060:
        fail("ping 1", f"model {model}")

    found, res = ph.broadcastPing(port)
    if res != COMM_SUCCESS or sorted(found) != [1, 2]:
        fail("broadcast ping", f"{ph.getTxRxResult(res)} {found}")

    baud, res, err = ph.read1ByteTxRx(port, 1, 8)
    ok("read baud", res, err, ph)
    if baud != 1:
        fail("read baud", f"index {baud}")

    res, err = ph.write1ByteTxRx(port, 1, 11, 1)  # velocity mode
    ok("write operating mode", res, err, ph)
    res, err = ph.write1ByteTxRx(port, 1, 64, 1)  # torque on
    ok("torque on", res, err, ph)
    res, err = ph.write1ByteTxRx(port, 1, 11, 4)  # EEPROM locked now
    if res != COMM_SUCCESS or err & 0x7F != 7:
        fail("eeprom lock", f"{ph.getTxRxResult(res)} error {err}")

    # Byte stuffing both ways: FF FF FD 00 through Indirect Data 1..4.
    res, err = ph.write4ByteTxRx(port, 2, 224, 0x00FDFFFF)
    ok("write stuffed", res, err, ph)
    value, res, err = ph.read4ByteTxRx(port, 2, 224)
    ok("read stuffed", res, err, ph)
    if value != 0x00FDFFFF:
        fail("read stuffed", hex(value))
    # Three FF before FD (a small negative velocity followed by an FD byte looks like this).
    res, err = ph.write4ByteTxRx(port, 2, 224, 0xFDFFFFFF)
    ok("write FF FF FF FD", res, err, ph)
    value, res, err = ph.read4ByteTxRx(port, 2, 224)
    ok("read FF FF FF FD", res, err, ph)
    if value != 0xFDFFFFFF:
        fail("read FF FF FF FD", hex(value))

    sync_read = GroupSyncRead(port, ph, 132, 4)
    for dxl_id in (1, 2):
        sync_read.addParam(dxl_id)
    if sync_read.txRxPacket() != COMM_SUCCESS:
        fail("sync read", "first")
    start = [sync_read.getData(i, 132, 4) for i in (1, 2)]

    sync_write = GroupSyncWrite(port, ph, 104, 4)
    sync_write.addParam(1, [131, 0, 0, 0])  # 131 × 0.229 rpm ≈ 30 rpm
    if sync_write.txPacket() != COMM_SUCCESS:
        fail("sync write", "goal velocity")
    time.sleep(0.3)

    # Motion checked against the servo's own clock (a busy CI machine may delay the
    # simulator, never its internal consistency): one read of Realtime Tick (120) through
    # Present Position (132) is a consistent snapshot.
    def snapshot():
        data, res, err = ph.readTxRx(port, 1, 120, 16)
        ok("read 120..135", res, err, ph)
        tick = data[0] | data[1] << 8
        vel = int.from_bytes(bytes(data[8:12]), "little", signed=True)
        pos = int.from_bytes(bytes(data[12:16]), "little", signed=True)
        return tick, vel, pos

    tick_a, vel_a, pos_a = snapshot()
    if vel_a != 131:
        fail("present velocity", f"{vel_a} while running at goal 131")
    time.sleep(0.2)
    tick_b, vel_b, pos_b = snapshot()
    dt_s = ((tick_b - tick_a) % 32768) / 1000.0
    expected = 131 * 0.229 / 60.0 * 4096.0 * dt_s
    if dt_s <= 0 or abs((pos_b - pos_a) - expected) > 4 + 0.01 * expected:
        fail("driver motion", f"moved {pos_b - pos_a} pulses in {dt_s:.3f} s of servo time, expected {expected:.0f}")

    if sync_read.txRxPacket() != COMM_SUCCESS:
        fail("sync read", "second")
    for dxl_id in (1, 2):
        if not sync_read.isAvailable(dxl_id, 132, 4):
            fail("sync read", f"no data for {dxl_id}")
    now = [sync_read.getData(i, 132, 4) for i in (1, 2)]
    moved = [((n - s + 2**31) % 2**32) - 2**31 for n, s in zip(now, start)]
    if moved[0] <= 0:
        fail("driver motion", f"moved {moved[0]} pulses")
    # The follower obeys θ = φ (this test's law); both are read in one sync read, one
    # status packet apart.
    if abs(moved[1] - moved[0]) > 40:
        fail("follower motion", f"follower {moved[1]} vs driver {moved[0]}")

    bulk = GroupBulkRead(port, ph)
    bulk.addParam(1, 64, 1)
    bulk.addParam(2, 0, 2)
    if bulk.txRxPacket() != COMM_SUCCESS:
        fail("bulk read", "tx/rx")
    if bulk.getData(1, 64, 1) != 1 or bulk.getData(2, 0, 2) != 1060:
        fail("bulk read", f"{bulk.getData(1, 64, 1)} {bulk.getData(2, 0, 2)}")

    res, err = ph.write1ByteTxRx(port, 1, 64, 0)
    ok("torque off", res, err, ph)
    vel, res, err = ph.read4ByteTxRx(port, 1, 128)
    ok("present velocity", res, err, ph)
    if vel != 0:
        fail("present velocity", f"{vel} after torque off")

    res, err = ph.reboot(port, 2)
    ok("reboot", res, err, ph)
    port.closePort()
    print("SDK-CHECK OK")


main()
