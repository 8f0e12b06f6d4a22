#!/usr/bin/python3
"""az_peer: an Oriental Motor AZ "direct data operation" controller written on python3-pymodbus (a Modbus
stack we did not write), to test our axis driver against an independent peer.

Usage: az_peer.py --tcp PORT|0 --ports-file F [--units 1,2] [--seed N]
       az_peer.py --rtu DEVICE [--ports-file F] [--units 1,2] [--seed N]   (F written once serving)

Map (0-based, upper word first, 100 steps per degree), written from the AZ manual independently of our
regmap.c: block 0x58..0x67 (op data, op type, position, speed, accel, decel, current, trigger), input
command 0x7D (ZHOME 0x10, STOP 0x20, ALM-RST 0x80, level bits), status 0x7F (bit 4 home end, 5 ready,
7 alarm, 8 busy, 9 +limit, 10 -limit, 13 move, 14 in-pos), alarm 0x80..81, command position 0xC6,
feedback position 0xCC, serial 0x300 (uint32), firmware 0x302. Motion is at the commanded speed (no ramps), hard limits at ±90° raise alarm 0x66.
Test-only registers: 0x400 positioning noise in millidegrees (Gaussian), 0x401 = N: the next N moves land
0.5° past the target (to exercise the driver's retries), 0x402 counts move triggers.
"""
import argparse
import asyncio
import random
import sys
import time

from pymodbus.datastore import ModbusServerContext, ModbusSlaveContext
from pymodbus.datastore.store import BaseModbusDataBlock
from pymodbus.framer.rtu_framer import ModbusRtuFramer
from pymodbus.server.async_io import ModbusSerialServer, ModbusTcpServer

STEPS = 100.0
HARD = 90.0


def s32(hi, lo):
    v = (hi << 16) | lo
    return v - (1 << 32) if v & 0x80000000 else v


def u32(v):
    v = int(round(v)) & 0xFFFFFFFF
    return [v >> 16, v & 0xFFFF]


class Axis(BaseModbusDataBlock):
    VALID = set(range(0x58, 0x68)) | {0x7D, 0x7F, 0x80, 0x81, 0xC6, 0xC7, 0xCC, 0xCD, 0x300, 0x301, 0x302, 0x400, 0x401,
             0x402}

    def __init__(self, rng):
        self.address = 0
        self.default_value = 0
        self.values = {a: 0 for a in self.VALID}
        self.rng = rng
        self.pos = 0.0
        self.start = 0.0
        self.target = 0.0
        self.t0 = 0.0
        self.speed = 1.0
        self.moving = False
        self.alarm = 0
        self.homed = False
        self.homing = False
        self.lim = 0
        self.cmd = 0

    def update(self):
        if not self.moving:
            return
        dist = self.target - self.start
        t = time.monotonic() - self.t0
        travelled = min(abs(dist), self.speed * t)
        p = self.start + (travelled if dist >= 0 else -travelled)
        if abs(p) > HARD:
            p = HARD if p > 0 else -HARD
            self.moving = False
            self.alarm = 0x66
            self.lim = 1 if p > 0 else 2
        elif travelled >= abs(dist):
            self.moving = False
            p = self.target
            if self.homing:
                self.homing, self.homed = False, True
            else:
                if self.values[0x401] > 0:
                    self.values[0x401] -= 1
                    p += 0.5
                if self.values[0x400]:
                    p += self.rng.gauss(0, self.values[0x400] / 1000.0)
        self.pos = p

    def begin(self, target, speed):
        self.update()
        self.start, self.target, self.t0 = self.pos, target, time.monotonic()
        self.speed = max(speed, 0.01)
        self.moving = True
        self.lim = 0

    def validate(self, address, count=1):
        return all(a in self.VALID for a in range(address, address + count))

    def getValues(self, address, count=1):
        self.update()
        st = (1 << 4 if self.homed else 0) | (1 << 7 if self.alarm else 0)
        if self.moving:
            st |= 1 << 8 | 1 << 13
        elif not self.alarm:
            st |= 1 << 5 | 1 << 14
        st |= (1 << 9 if self.lim == 1 else 0) | (1 << 10 if self.lim == 2 else 0)
        self.values[0x7F] = st
        self.values[0x80], self.values[0x81] = u32(self.alarm)
        self.values[0xC6], self.values[0xC7] = u32((self.target if self.moving else self.pos) * STEPS)
        self.values[0xCC], self.values[0xCD] = u32(self.pos * STEPS)
        self.values[0x300], self.values[0x301] = u32(4242)
        self.values[0x302] = 7
        return [self.values[a] for a in range(address, address + count)]

    def setValues(self, address, values):
        for i, v in enumerate(values):
            self.values[address + i] = v
        span = range(address, address + len(values))
        if 0x7D in span:
            new = self.values[0x7D]
            rising = new & ~self.cmd
            self.cmd = new
            if rising & 0x20:  # STOP (immediate in this peer)
                self.update()
                self.moving = self.homing = False
            if rising & 0x80:  # ALM-RST
                self.alarm = 0
            if rising & 0x10 and not self.alarm:  # ZHOME
                self.homing, self.homed = True, False
                self.begin(0.0, 50.0)
        if 0x67 in span and s32(self.values[0x66], self.values[0x67]) == 1 and not self.alarm:
            self.values[0x402] += 1
            if s32(self.values[0x5A], self.values[0x5B]) != 1:
                self.alarm = 0x70
                return
            target = s32(self.values[0x5C], self.values[0x5D]) / STEPS
            speed = s32(self.values[0x5E], self.values[0x5F]) / STEPS
            self.homing = False
            self.begin(target, speed)


async def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--tcp", type=int)
    ap.add_argument("--rtu")
    ap.add_argument("--ports-file")
    ap.add_argument("--units", default="1,2")
    ap.add_argument("--seed", type=int, default=1)
    a = ap.parse_args()
    rng = random.Random(a.seed)
    slaves = {}
    for u in (int(x) for x in a.units.split(",")):
        slaves[u] = ModbusSlaveContext(hr=Axis(rng), zero_mode=True)
    ctx = ModbusServerContext(slaves=slaves, single=False)
    if a.rtu:
        server = ModbusSerialServer(ctx, framer=ModbusRtuFramer, port=a.rtu, baudrate=115200,
                                    ignore_missing_slaves=True)
        await server.start()
        if a.ports_file:  # readiness: the serial port is open and served
            import os
            with open(a.ports_file + ".tmp", "w") as f:
                f.write("%s\n" % a.rtu)
            os.rename(a.ports_file + ".tmp", a.ports_file)
        print("az_peer: serving RTU on", a.rtu, flush=True)
        while True:
            await asyncio.sleep(3600)
    server = ModbusTcpServer(ctx, address=("127.0.0.1", a.tcp or 0), allow_reuse_address=True)
    task = asyncio.create_task(server.serve_forever())
    await server.serving
    port = server.server.sockets[0].getsockname()[1]
    if a.ports_file:
        with open(a.ports_file + ".tmp", "w") as f:
            f.write(f"{port}\n")
        import os
        os.rename(a.ports_file + ".tmp", a.ports_file)
    print("az_peer: serving TCP on port", port, flush=True)
    await task


if __name__ == "__main__":
    try:
        asyncio.run(main())
    except KeyboardInterrupt:
        sys.exit(0)
