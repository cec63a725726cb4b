# cython: language_level=3, boundscheck=False, wraparound=False, cdivision=True
# cython: initializedcheck=False, infer_types=False
"""The compiled `FrameStore`: the same samples, walks and results as bridge/tf/store.py, to
the bit, with each frame's samples in one C array and the walks in C.

Why it exists: a 7-link robot's /tf at 1 kHz is 7,000 samples stored and 7,000 lookups
composed a second; bench/bench_tf.py measures what reading and storing one such message
costs in store.py and here. store.py is the reference: read it first, this file follows it
function by function (same names), and tests/bridge/test_tf_store_equivalence.py runs both
on the same random histories. Built by setup.py where a C compiler is found (Cython, build-time only);
`TfBuffer` falls back to store.py otherwise.

Bits: every formula is store.py's and bridge/tf/math.py's in the same order of operations,
compiled with -ffp-contract=off (no fused multiply-add), so results match exactly.
"""

from cpython.mem cimport PyMem_Free, PyMem_Malloc, PyMem_Realloc
from cpython.unicode cimport PyUnicode_DecodeUTF8
from libc.math cimport acos, isfinite, sin, sqrt
from libc.stdint cimport int32_t, int64_t, uint32_t
from libc.string cimport memcpy, memmove

import sys

from bridge.tf.errors import ConnectivityError, ExtrapolationError, TfError, TfLookupError

# The store interface this module implements (buffer.STORE_INTERFACE): bump both together.
INTERFACE = 6

# CDR's doubles are read as the machine's: on a big-endian machine `insert_cdr` declines.
cdef bint LITTLE_ENDIAN = sys.byteorder == "little"

cdef int64_t NO_STAMP = 0x7FFFFFFFFFFFFFFF  # above any stamp the API accepts (< 2**63)
cdef double QUATERNION_TOLERANCE = 1e-2  # tf2's, as in buffer.py
cdef double SLERP_LINEAR_DOT = 0.9999995  # bridge/tf/math.py


cdef struct Sample:
    int64_t stamp
    Py_ssize_t parent  # frame id
    double v[7]  # tx, ty, tz, qx, qy, qz, qw


cdef struct Frame:
    bint cached  # a child frame: it has samples (a frame seen only as a parent has none)
    bint static
    int64_t received  # receive_tick of its last transform (store.py's _FrameCache.received)
    Sample *samples
    Py_ssize_t start  # samples[start:end] are kept; older ones were dropped in a chunk
    Py_ssize_t end
    Py_ssize_t cap
    # Scratch of the walks, valid while its epoch is the walk's.
    int64_t seen_epoch
    int64_t seen_low
    Py_ssize_t seen_below
    int64_t memo_epoch
    Py_ssize_t memo_top
    int64_t memo_t
    double memo_v[7]


cdef struct Slot:  # one link at a time: frame, older sample's index, ratio to the next
    Py_ssize_t frame
    Py_ssize_t index
    double ratio


# ---------------------------------------------------------------------- math.py, in C

cdef inline void compose(const double *a, const double *b, double *out) noexcept nogil:
    cdef double atx = a[0], aty = a[1], atz = a[2], qx = a[3], qy = a[4], qz = a[5], qw = a[6]
    cdef double btx = b[0], bty = b[1], btz = b[2], bx = b[3], by = b[4], bz = b[5], bw = b[6]
    cdef double cx = 2.0 * (qy * btz - qz * bty)
    cdef double cy = 2.0 * (qz * btx - qx * btz)
    cdef double cz = 2.0 * (qx * bty - qy * btx)
    out[0] = atx + btx + qw * cx + qy * cz - qz * cy
    out[1] = aty + bty + qw * cy + qz * cx - qx * cz
    out[2] = atz + btz + qw * cz + qx * cy - qy * cx
    out[3] = qw * bx + qx * bw + qy * bz - qz * by
    out[4] = qw * by - qx * bz + qy * bw + qz * bx
    out[5] = qw * bz + qx * by - qy * bx + qz * bw
    out[6] = qw * bw - qx * bx - qy * by - qz * bz


cdef inline void invert(const double *a, double *out) noexcept nogil:
    # quat_rotate((-qx, -qy, -qz, qw), (-tx, -ty, -tz)), as math.invert calls it.
    cdef double qx = -a[3], qy = -a[4], qz = -a[5], qw = a[6]
    cdef double vx = -a[0], vy = -a[1], vz = -a[2]
    cdef double cx = 2.0 * (qy * vz - qz * vy)
    cdef double cy = 2.0 * (qz * vx - qx * vz)
    cdef double cz = 2.0 * (qx * vy - qy * vx)
    out[0] = vx + qw * cx + qy * cz - qz * cy
    out[1] = vy + qw * cy + qz * cx - qx * cz
    out[2] = vz + qw * cz + qx * cy - qy * cx
    out[3] = -a[3]
    out[4] = -a[4]
    out[5] = -a[5]
    out[6] = a[6]


cdef inline void interpolate(const double *a, const double *b, double ratio,
                             double *out) noexcept nogil:
    cdef double r0 = 1.0 - ratio
    # quat_slerp(a[3:], b[3:], ratio)
    cdef double ax = a[3], ay = a[4], az = a[5], aw = a[6]
    cdef double bx = b[3], by = b[4], bz = b[5], bw = b[6]
    cdef double dot = ax * bx + ay * by + az * bz + aw * bw
    cdef double wa, wb, theta, s, x, y, z, w, n
    if dot < 0.0:
        bx = -bx
        by = -by
        bz = -bz
        bw = -bw
        dot = -dot
    if dot > SLERP_LINEAR_DOT:
        wa = 1.0 - ratio
        wb = ratio
    else:
        theta = acos(dot)
        s = sin(theta)
        wa = sin((1.0 - ratio) * theta) / s
        wb = sin(ratio * theta) / s
    x = wa * ax + wb * bx
    y = wa * ay + wb * by
    z = wa * az + wb * bz
    w = wa * aw + wb * bw
    n = sqrt(x * x + y * y + z * z + w * w)
    out[0] = r0 * a[0] + ratio * b[0]
    out[1] = r0 * a[1] + ratio * b[1]
    out[2] = r0 * a[2] + ratio * b[2]
    out[3] = x / n
    out[4] = y / n
    out[5] = z / n
    out[6] = w / n


cdef inline void set_identity(double *v) noexcept nogil:
    v[0] = 0.0
    v[1] = 0.0
    v[2] = 0.0
    v[3] = 0.0
    v[4] = 0.0
    v[5] = 0.0
    v[6] = 1.0


# ---------------------------------------------------------------------- CDR (codecs/cdr.py)

cdef struct Raw:  # one TransformStamped as read
    int32_t sec
    uint32_t nanosec
    Py_ssize_t frame_at  # offset and length (without the NUL) of frame_id
    Py_ssize_t frame_len
    Py_ssize_t child_at
    Py_ssize_t child_len
    double v[7]


cdef inline uint32_t read_u32(const unsigned char *p) noexcept nogil:
    return p[0] | (<uint32_t>p[1] << 8) | (<uint32_t>p[2] << 16) | (<uint32_t>p[3] << 24)


cdef int read_string(const unsigned char *p, Py_ssize_t size, Py_ssize_t *offset,
                     Py_ssize_t *at, Py_ssize_t *length) noexcept nogil:
    """The CDR string at offset (aligned to 4): 0 and the offset after it, or -1."""
    cdef Py_ssize_t o = offset[0]
    cdef uint32_t n
    if o + 4 > size:
        return -1
    n = read_u32(p + o)
    if n == 0 or o + 4 + <Py_ssize_t>n > size:
        return -1
    at[0] = o + 4
    length[0] = n - 1
    offset[0] = o + 4 + n
    return 0


cdef Py_ssize_t read_tf_message(const unsigned char *p, Py_ssize_t size,
                                Raw **out) noexcept:
    """The transforms of a TFMessage (little-endian plain CDR), or -1: codecs/cdr.py's
    read_tf_message, which raises CdrError where this returns -1."""
    cdef uint32_t count
    cdef Py_ssize_t offset = 8, k
    cdef Raw *rows
    if size < 8 or p[0] != 0 or p[1] != 1:
        return -1
    count = read_u32(p + 4)
    if count > <uint32_t>((size - 8) // 72):  # 72: the smallest TransformStamped
        return -1
    if count == 0:
        out[0] = NULL
        return 0
    rows = <Raw *>PyMem_Malloc(count * sizeof(Raw))
    if rows == NULL:
        return -1
    for k in range(count):
        if offset + 8 > size:
            PyMem_Free(rows)
            return -1
        rows[k].sec = <int32_t>read_u32(p + offset)
        rows[k].nanosec = read_u32(p + offset + 4)
        offset += 8
        if read_string(p, size, &offset, &rows[k].frame_at, &rows[k].frame_len) < 0:
            PyMem_Free(rows)
            return -1
        offset += (-(offset - 4)) & 3
        if read_string(p, size, &offset, &rows[k].child_at, &rows[k].child_len) < 0:
            PyMem_Free(rows)
            return -1
        offset += (-(offset - 4)) & 7
        if offset + 56 > size:
            PyMem_Free(rows)
            return -1
        memcpy(rows[k].v, p + offset, 56)  # little-endian doubles on every ROS 2 platform
        offset += 56
    out[0] = rows
    return count


# ---------------------------------------------------------------------- the store

cdef class CompiledFrameStore:
    """store.FrameStore's interface, plus `insert_cdr` (read and store a TFMessage)."""

    cdef Frame *_frames  # by frame id
    cdef Py_ssize_t _count  # frame ids in use
    cdef Py_ssize_t _capacity
    cdef Py_ssize_t _cached  # frames with samples (store.py's len(self._frames))
    cdef list _names  # frame id -> name
    cdef dict _ids  # name -> frame id
    cdef int64_t _window_ns
    cdef int64_t _epoch  # of the walks' scratch (seen_*)
    cdef int64_t _memo_epoch  # of one latest_many batch (memo_*)
    cdef Slot *_src
    cdef Slot *_tgt
    cdef Py_ssize_t *_chain_src
    cdef Py_ssize_t *_chain_tgt
    cdef public long long graph_version
    cdef public long long receive_tick  # store.py's: when the transforms inserted next came
    cdef Py_ssize_t _max_frames  # 0: no bound (TfBuffer's, see buffer.py)
    cdef Py_ssize_t _max_name  # characters of a frame id; 0: no bound

    def __cinit__(self, long long window_ns, Py_ssize_t max_frames=0,
                  Py_ssize_t max_name=0):
        # C fields start at 0 / NULL (the allocation is zeroed).
        self._window_ns = window_ns
        self._max_frames = max_frames
        self._max_name = max_name
        self._names = []
        self._ids = {}

    def __dealloc__(self):
        self._free_frames()

    cdef void _free_frames(self) noexcept:
        cdef Py_ssize_t k
        for k in range(self._count):
            PyMem_Free(self._frames[k].samples)
        PyMem_Free(self._frames)
        PyMem_Free(self._src)
        PyMem_Free(self._tgt)
        PyMem_Free(self._chain_src)
        PyMem_Free(self._chain_tgt)
        self._frames = NULL
        self._src = NULL
        self._tgt = NULL
        self._chain_src = NULL
        self._chain_tgt = NULL
        self._count = 0
        self._capacity = 0
        self._cached = 0

    cdef Py_ssize_t _id(self, str name) except -1:
        """The frame id of ``name``, made if new (with room in every scratch array)."""
        cdef object found = self._ids.get(name)
        cdef Py_ssize_t fid, capacity
        if found is not None:
            return <Py_ssize_t>found
        if self._count == self._capacity:
            capacity = self._capacity * 2 if self._capacity else 16
            self._frames = <Frame *>grow(self._frames, capacity * sizeof(Frame))
            # The walks' scratch: a chain may hold every frame, and one more before the loop
            # check fires.
            self._src = <Slot *>grow(self._src, (capacity + 1) * sizeof(Slot))
            self._tgt = <Slot *>grow(self._tgt, (capacity + 1) * sizeof(Slot))
            self._chain_src = <Py_ssize_t *>grow(self._chain_src,
                                                 (capacity + 1) * sizeof(Py_ssize_t))
            self._chain_tgt = <Py_ssize_t *>grow(self._chain_tgt,
                                                 (capacity + 1) * sizeof(Py_ssize_t))
            self._capacity = capacity
        fid = self._count
        self._frames[fid].cached = False
        self._frames[fid].static = False
        self._frames[fid].received = 0
        self._frames[fid].samples = NULL
        self._frames[fid].start = 0
        self._frames[fid].end = 0
        self._frames[fid].cap = 0
        self._frames[fid].seen_epoch = -1
        self._frames[fid].memo_epoch = -1
        self._count += 1
        self._names.append(name)
        self._ids[name] = fid
        return fid

    # ------------------------------------------------------------------ writing

    def insert(self, str parent, str child, long long stamp, tuple value, bint static):
        """Store one checked sample; False if it changed nothing (a repeat, or too old)."""
        cdef double v[7]
        cdef Py_ssize_t k
        for k in range(7):
            v[k] = value[k]
        return self._insert(parent, child, stamp, v, static) == 1

    cdef int _insert(self, str parent, str child, int64_t stamp, const double *v,
                     bint static) except -1:
        cdef bint new_parent = parent not in self._ids
        cdef bint new_child = child not in self._ids
        cdef Py_ssize_t pid = self._id(parent)
        cdef Py_ssize_t cid = self._id(child)
        cdef Frame *f = &self._frames[cid]
        cdef Sample *s
        cdef Py_ssize_t i, lo, hi, mid, n
        cdef int64_t window = self._window_ns
        if new_child or new_parent:
            self.graph_version += 1
        if not f.cached or f.static != static:
            self._reserve(f, 1)  # first, so that running out of memory changes nothing
            if not f.cached:
                self._cached += 1
            f.cached = True
            f.static = static
            f.start = 0
            f.end = 0
            self.graph_version += 1
        f.received = self.receive_tick  # a repeat or too old still says it is alive
        if static:
            if f.end > f.start:
                s = &f.samples[f.start]
                if s.parent == pid and same7(s.v, v):
                    return 0
                if s.parent != pid:
                    self.graph_version += 1
            self._reserve(f, 1)
            f.start = 0
            f.end = 1
            put(&f.samples[0], 0, pid, v)
            return 1
        if f.end == f.start or stamp > f.samples[f.end - 1].stamp:
            if f.end > f.start and f.samples[f.end - 1].parent != pid:
                self.graph_version += 1
            self._reserve(f, f.end - f.start + 1)
            put(&f.samples[f.end], stamp, pid, v)
            f.end += 1
            # store.py drops samples older than the window a quarter window at a time.
            if f.samples[f.start].stamp < stamp - window - (window >> 2):
                f.start = bisect_left(f, stamp - window)
            return 1
        if stamp < f.samples[f.end - 1].stamp - window:
            return 0
        i = bisect_left(f, stamp)
        s = &f.samples[i]
        if s.stamp == stamp:
            if s.parent == pid and same7(s.v, v):
                return 0
            if i == f.end - 1 and s.parent != pid:
                self.graph_version += 1
            put(s, stamp, pid, v)
            return 1
        n = f.end - f.start
        lo = i - f.start
        self._reserve(f, n + 1)
        i = f.start + lo  # _reserve may have moved the samples to the front
        memmove(&f.samples[i + 1], &f.samples[i], (f.end - i) * sizeof(Sample))
        put(&f.samples[i], stamp, pid, v)
        f.end += 1
        return 1

    cdef int _reserve(self, Frame *f, Py_ssize_t needed) except -1:
        """Room for ``needed`` samples from f.start on, moving the kept ones to the front
        (dropping the chunk for good) when that makes the room."""
        cdef Py_ssize_t kept = f.end - f.start, cap
        if f.start + needed <= f.cap:
            return 0
        if f.start and needed <= f.cap:
            memmove(f.samples, &f.samples[f.start], kept * sizeof(Sample))
            f.start = 0
            f.end = kept
            return 0
        cap = max(needed + (needed >> 1), 8)
        if f.start:
            memmove(f.samples, &f.samples[f.start], kept * sizeof(Sample))
            f.start = 0
            f.end = kept
        f.samples = <Sample *>grow(f.samples, cap * sizeof(Sample))
        f.cap = cap
        return 0

    def insert_cdr(self, const unsigned char[::1] data, bint static):
        """Read a serialized TFMessage (bytes, or a view such as the rcl reader's) and store
        its transforms, as `TfBuffer.set_transforms` of it would: (changed child frames,
        refused) with ``refused`` a list of (index, (sec, nanosec, frame, child, tx, ty, tz,
        qx, qy, qz, qw)) for `TfBuffer` to word. None, with nothing stored, for bytes this
        does not read (not little-endian CDR)."""
        cdef Py_ssize_t size = data.shape[0]
        cdef const unsigned char *p = &data[0] if size else <const unsigned char *>b""
        cdef Raw *rows = NULL
        cdef Py_ssize_t count = read_tf_message(p, size, &rows)
        cdef list names = []
        cdef Py_ssize_t k
        if count < 0 or not LITTLE_ENDIAN:
            PyMem_Free(rows)
            return None
        try:
            # Decode every frame id first: bytes that are not UTF-8 store nothing.
            for k in range(count):
                names.append(self._name(p, rows[k].frame_at, rows[k].frame_len))
                names.append(self._name(p, rows[k].child_at, rows[k].child_len))
        except UnicodeDecodeError:
            PyMem_Free(rows)
            return None
        try:
            return self._store_rows(rows, count, names, static)
        finally:
            PyMem_Free(rows)

    cdef str _name(self, const unsigned char *p, Py_ssize_t at, Py_ssize_t length):
        """A frame id; one far over the bound (a peer's 1 MB ids) only as much of it as
        shows that, and marked cut: it is refused, and a megabyte string a frame id would
        be made for nothing (and stay in the heap)."""
        cdef Py_ssize_t most = 4 * self._max_name  # UTF-8: at most 4 bytes a character
        if self._max_name and length > most:
            return PyUnicode_DecodeUTF8(<const char *>p + at, most, "replace") + "\u2026"
        return PyUnicode_DecodeUTF8(<const char *>p + at, length, NULL)

    cdef tuple _store_rows(self, Raw *rows, Py_ssize_t count, list names, bint static):
        cdef set changed = set()
        cdef list refused = []
        cdef Py_ssize_t k
        cdef str parent, child
        cdef int64_t stamp
        cdef double v[7]
        cdef double norm2, n
        cdef Raw *r
        cdef bint over
        for k in range(count):
            r = &rows[k]
            parent = names[2 * k]
            child = names[2 * k + 1]
            # buffer.py's _check, for what CDR can carry; a refusal is worded there.
            if parent.startswith("/"):
                parent = parent[1:]
            if child.startswith("/"):
                child = child[1:]
            stamp = 0 if static else <int64_t>r.sec * 1000000000 + r.nanosec
            memcpy(v, r.v, sizeof(v))
            # TfBuffer's bounds (it words them): a frame id too long, a frame past the count.
            over = ((self._max_name and (len(parent) > self._max_name
                                         or len(child) > self._max_name))
                    or (self._max_frames and self._count + 2 > self._max_frames
                        and self._new_past_bound(parent, child)))
            norm2 = v[3] * v[3] + v[4] * v[4] + v[5] * v[5] + v[6] * v[6]
            if (over or not child or not parent or parent == child or stamp < 0
                    or not (isfinite(v[0]) and isfinite(v[1]) and isfinite(v[2])
                            and isfinite(v[3]) and isfinite(v[4]) and isfinite(v[5])
                            and isfinite(v[6]))
                    or not abs(norm2 - 1.0) < QUATERNION_TOLERANCE):
                refused.append((k, (r.sec, r.nanosec, names[2 * k], names[2 * k + 1],
                                    r.v[0], r.v[1], r.v[2], r.v[3], r.v[4], r.v[5], r.v[6])))
                continue
            if norm2 != 1.0:
                n = sqrt(norm2)
                v[3] = v[3] / n
                v[4] = v[4] / n
                v[5] = v[5] / n
                v[6] = v[6] / n
            if self._insert(parent, child, stamp, v, static):
                changed.add(child)
        return changed, refused

    cdef bint _new_past_bound(self, str parent, str child):
        """Whether parent<-child names a new frame past ``max_frames`` (TfBuffer may still
        take it into its reserve; frames already known are always stored)."""
        cdef Py_ssize_t new = (parent not in self._ids) + (child not in self._ids)
        return new > 0 and self._count + new > self._max_frames

    def clear(self):
        self._free_frames()
        self._names = []
        self._ids = {}
        self.graph_version += 1

    # ------------------------------------------------------------------ reading

    def known(self):
        return list(self._names)

    @property
    def frame_count(self):
        return self._count

    def has_frame(self, str frame):
        return frame in self._ids

    def frame_rows(self):
        cdef list out = []
        cdef Frame *f
        cdef Py_ssize_t first
        for name in sorted(self._cached_names()):
            f = &self._frames[<Py_ssize_t>self._ids[name]]
            first = first_live(f, self._window_ns)
            out.append((name, self._names[f.samples[f.end - 1].parent], f.static,
                        f.samples[f.end - 1].stamp, f.samples[first].stamp, f.end - first))
        return out

    def receipts(self):
        """One (frame, newest parent, static, receive tick) per child frame."""
        cdef Frame *f
        cdef Py_ssize_t k
        cdef list out = []
        for k in range(self._count):
            f = &self._frames[k]
            if f.cached:
                out.append((self._names[k], self._names[f.samples[f.end - 1].parent], f.static,
                            f.received))
        return out

    def samples_of(self, str frame):
        """The live samples of a child frame, oldest first: (stamp, parent, value)."""
        cdef Frame *f = &self._frames[<Py_ssize_t>self._ids[frame]]
        cdef Py_ssize_t i
        cdef Sample *s
        cdef list out = []
        for i in range(first_live(f, self._window_ns), f.end):
            s = &f.samples[i]
            out.append((s.stamp, self._names[s.parent],
                        (s.v[0], s.v[1], s.v[2], s.v[3], s.v[4], s.v[5], s.v[6])))
        return out

    cdef list _cached_names(self):
        cdef Py_ssize_t k
        return [self._names[k] for k in range(self._count) if self._frames[k].cached]

    def lookup(self, str target, str source, long long t):
        cdef double v[7]
        cdef int64_t used = self._lookup(target, source, t, False, v)
        return used, (v[0], v[1], v[2]), (v[3], v[4], v[5], v[6])

    def latest_many(self, pairs):
        cdef list out = []
        cdef double v[7]
        cdef int64_t used
        self._memo_epoch += 1  # a new memo for this batch
        for target, source in pairs:
            try:
                used = self._lookup(target, source, 0, True, v)
            except TfError as error:
                out.append(error)
                continue
            out.append((used, (v[0], v[1], v[2]), (v[3], v[4], v[5], v[6])))
        return out

    def chain_frames(self, str target, str source):
        cdef Py_ssize_t ns, nt, k
        cdef int64_t low
        if target == source:
            return frozenset()
        self._require(target, "lookupTransform argument target_frame")
        self._require(source, "lookupTransform argument source_frame")
        self._latest_chain(target, source, &low, &ns, &nt)
        return frozenset([self._names[self._chain_src[k]] for k in range(ns)]
                         + [self._names[self._chain_tgt[k]] for k in range(nt)])

    # ------------------------------------------------------------------ internals

    cdef int64_t _lookup(self, str target, str source, int64_t t, bint memo,
                         double *out) except? -1:
        cdef Py_ssize_t ns, nt, top
        cdef Frame *f
        cdef double a[7]
        cdef double b[7]
        cdef double inv[7]
        cdef int found
        cdef bint walk
        if target == source:  # tf2 answers identity even for unknown frames
            found = self._ids.get(target, -1)
            if found >= 0:
                f = &self._frames[found]
                if t == 0 and f.cached and not f.static:
                    t = f.samples[f.end - 1].stamp
            set_identity(out)
            return t
        self._require(target, "lookupTransform argument target_frame")
        self._require(source, "lookupTransform argument source_frame")
        if t != 0:
            self._walk(target, source, t, out)
            return t
        self._latest_chain(target, source, &t, &ns, &nt)
        if ns:
            f = &self._frames[self._chain_src[ns - 1]]
            top = f.samples[f.end - 1].parent
        else:
            top = self._ids[source]
        try:
            walk = not self._up_at(self._chain_src, ns, t, top, memo, a)  # top<-source
            if not walk and nt:
                walk = not self._up_at(self._chain_tgt, nt, t, top, memo, b)  # top<-target
        except ExtrapolationError as exc:
            raise exc.with_frames(source, target) from None
        if walk:  # a frame had another parent at t: walk again at t
            self._walk(target, source, t, out)
            return t
        if not nt:
            memcpy(out, a, sizeof(a))
            return t
        invert(b, inv)
        compose(inv, a, out)
        return t

    cdef int _require(self, str frame, str argument) except -1:
        if frame not in self._ids:
            raise TfLookupError.unknown_frame(frame, argument)
        return 0

    cdef object _loop_error(self):
        cdef Frame *f
        listing = []
        for name in sorted(self._cached_names()):
            f = &self._frames[<Py_ssize_t>self._ids[name]]
            listing.append(f"Frame {name} exists with parent "
                           f"{self._names[f.samples[f.end - 1].parent]}.\n")
        return TfLookupError("The tf tree is invalid because it contains a loop.\n"
                             + "".join(listing))

    cdef int _locate(self, Frame *f, int64_t t, Slot *slot) except -1:
        """store._locate: slot.index / slot.ratio of f at t (0: newest); slot.frame is set
        to f's parent there. Raises ExtrapolationError."""
        cdef Py_ssize_t n = f.end - f.start, first, i
        cdef int64_t last, s0
        if f.static:
            slot.frame = f.samples[f.start].parent
            slot.index = f.start
            slot.ratio = 0.0
            return 0
        last = f.samples[f.end - 1].stamp
        if t == last or t == 0:
            slot.frame = f.samples[f.end - 1].parent
            slot.index = f.end - 1
            slot.ratio = 0.0
            return 0
        if n == 1:
            raise ExtrapolationError("single", t, last)
        if t > last:
            raise ExtrapolationError("future", t, last)
        first = first_live(f, self._window_ns)
        if t < f.samples[first].stamp:
            raise ExtrapolationError("past", t, f.samples[first].stamp)
        if f.end - first == 1:
            raise ExtrapolationError("single", t, last)
        i = bisect_right(f, t) - 1
        s0 = f.samples[i].stamp
        slot.frame = f.samples[i].parent
        slot.index = i
        if s0 == t or f.samples[i].parent != f.samples[i + 1].parent:
            slot.ratio = 0.0
        else:
            slot.ratio = <double>(t - s0) / <double>(f.samples[i + 1].stamp - s0)
        return 0

    cdef void _value(self, Py_ssize_t frame, Slot *slot, double *out) noexcept:
        cdef Frame *f = &self._frames[frame]
        if slot.ratio == 0.0:
            memcpy(out, f.samples[slot.index].v, 7 * sizeof(double))
        else:
            interpolate(f.samples[slot.index].v, f.samples[slot.index + 1].v, slot.ratio, out)

    cdef bint _up_at(self, Py_ssize_t *chain, Py_ssize_t n, int64_t t, Py_ssize_t top,
                     bint memo, double *acc) except? False:
        """store._up_at: top<-chain[0] at t into acc; False if a frame had another parent
        at t. With ``memo``, each frame's top<-frame of this batch is kept on the frame."""
        cdef Py_ssize_t k, below = 0, frame
        cdef Frame *f
        cdef Slot *slots = self._src if chain == self._chain_src else self._tgt
        cdef bint have = False
        cdef double value[7]
        cdef double tmp[7]
        for k in range(n):
            frame = chain[k]
            f = &self._frames[frame]
            if (memo and f.memo_epoch == self._memo_epoch and f.memo_top == top
                    and f.memo_t == t):
                memcpy(acc, f.memo_v, 7 * sizeof(double))
                have = True
                break
            self._locate(f, t, &slots[below])
            if slots[below].frame != f.samples[f.end - 1].parent:
                return False
            below += 1
        for k in range(below - 1, -1, -1):
            frame = chain[k]
            self._value(frame, &slots[k], value)
            if have:
                compose(acc, value, tmp)
                memcpy(acc, tmp, sizeof(tmp))
            else:
                memcpy(acc, value, sizeof(value))
                have = True
            if memo:
                f = &self._frames[frame]
                f.memo_epoch = self._memo_epoch
                f.memo_top = top
                f.memo_t = t
                memcpy(f.memo_v, acc, sizeof(value))
        if not have:
            set_identity(acc)
        return True

    cdef int _latest_chain(self, str target, str source, int64_t *t, Py_ssize_t *ns,
                           Py_ssize_t *nt) except -1:
        """store._latest_chain: the latest common time, and the frames below the common
        ancestor on each side (self._chain_src / self._chain_tgt, bottom-up)."""
        cdef int64_t epoch, low = NO_STAMP, stamp
        cdef Py_ssize_t frame = self._ids[source], tid = self._ids[target], n_src = 0
        cdef Py_ssize_t n_tgt = 0, limit = self._cached
        cdef Frame *f
        self._epoch += 1
        epoch = self._epoch
        while True:
            f = &self._frames[frame]
            if f.seen_epoch == epoch:
                raise self._loop_error()
            f.seen_epoch = epoch
            f.seen_low = low
            f.seen_below = n_src
            if frame == tid:
                t[0] = 0 if low == NO_STAMP else low
                ns[0] = n_src
                nt[0] = 0
                return 0
            if not f.cached:
                break
            stamp = f.samples[f.end - 1].stamp
            if not f.static and stamp < low:
                low = stamp
            self._chain_src[n_src] = frame
            n_src += 1
            frame = f.samples[f.end - 1].parent
        low = NO_STAMP
        frame = tid
        while self._frames[frame].seen_epoch != epoch:
            f = &self._frames[frame]
            if not f.cached:
                raise ConnectivityError(target, source)
            stamp = f.samples[f.end - 1].stamp
            if not f.static and stamp < low:
                low = stamp
            if n_tgt == limit:  # store.py raises once len(tgt) > limit
                raise self._loop_error()
            self._chain_tgt[n_tgt] = frame
            n_tgt += 1
            frame = f.samples[f.end - 1].parent
        f = &self._frames[frame]
        if f.seen_low < low:
            low = f.seen_low
        t[0] = 0 if low == NO_STAMP else low
        ns[0] = f.seen_below
        nt[0] = n_tgt
        return 0

    cdef int _walk(self, str target, str source, int64_t t, double *out) except -1:
        """store._walk: target<-source at t, following each frame's parent at t."""
        cdef int64_t epoch
        cdef Py_ssize_t frame = self._ids[source], tid = self._ids[target]
        cdef Py_ssize_t n_src = 0, n_tgt = 0, limit = self._cached
        cdef Frame *f
        cdef object src_error = None
        cdef double a[7]
        cdef double b[7]
        cdef double inv[7]
        self._epoch += 1
        epoch = self._epoch
        while True:
            f = &self._frames[frame]
            if f.seen_epoch == epoch:
                raise self._loop_error()
            f.seen_epoch = epoch
            f.seen_below = n_src
            if frame == tid or not f.cached:
                break
            try:
                self._locate(f, t, &self._src[n_src])
            except ExtrapolationError as exc:
                src_error = exc  # not fatal yet: the target side may meet the chain below
                break
            self._chain_src[n_src] = frame
            frame = self._src[n_src].frame
            n_src += 1
        frame = tid
        while self._frames[frame].seen_epoch != epoch:
            f = &self._frames[frame]
            if not f.cached:
                if src_error is not None:
                    raise src_error.with_frames(source, target)
                raise ConnectivityError(target, source)
            try:
                self._locate(f, t, &self._tgt[n_tgt])
            except ExtrapolationError as exc:
                raise exc.with_frames(source, target) from None
            self._chain_tgt[n_tgt] = frame
            frame = self._tgt[n_tgt].frame
            n_tgt += 1
            if n_tgt > limit:
                raise self._loop_error()
        n_src = self._frames[frame].seen_below
        self._up(self._chain_src, self._src, n_src, a)  # common<-source
        if not n_tgt:
            memcpy(out, a, sizeof(a))
            return 0
        self._up(self._chain_tgt, self._tgt, n_tgt, b)
        invert(b, inv)
        compose(inv, a, out)
        return 0

    cdef void _up(self, Py_ssize_t *frames, Slot *slots, Py_ssize_t n,
                  double *acc) noexcept:
        """store._up: the links listed bottom-up, composed top-down."""
        cdef Py_ssize_t k
        cdef double value[7]
        cdef double tmp[7]
        if n == 0:
            set_identity(acc)
            return
        self._value(frames[n - 1], &slots[n - 1], acc)
        for k in range(n - 2, -1, -1):
            self._value(frames[k], &slots[k], value)
            compose(acc, value, tmp)
            memcpy(acc, tmp, sizeof(tmp))


# ---------------------------------------------------------------------- helpers

cdef void *grow(void *p, size_t size) except NULL:
    """PyMem_Realloc, raising MemoryError (p is left as it was) instead of returning NULL."""
    cdef void *grown = PyMem_Realloc(p, size)
    if grown == NULL:
        raise MemoryError()
    return grown


cdef inline bint same7(const double *a, const double *b) noexcept nogil:
    cdef int k
    for k in range(7):
        if a[k] != b[k]:
            return False
    return True


cdef inline void put(Sample *s, int64_t stamp, Py_ssize_t parent, const double *v) noexcept nogil:
    s.stamp = stamp
    s.parent = parent
    memcpy(s.v, v, 7 * sizeof(double))


cdef inline Py_ssize_t bisect_left(Frame *f, int64_t stamp) noexcept nogil:
    cdef Py_ssize_t lo = f.start, hi = f.end, mid
    while lo < hi:
        mid = (lo + hi) // 2
        if f.samples[mid].stamp < stamp:
            lo = mid + 1
        else:
            hi = mid
    return lo


cdef inline Py_ssize_t bisect_right(Frame *f, int64_t stamp) noexcept nogil:
    cdef Py_ssize_t lo = f.start, hi = f.end, mid
    while lo < hi:
        mid = (lo + hi) // 2
        if stamp < f.samples[mid].stamp:
            hi = mid
        else:
            lo = mid + 1
    return lo


cdef inline Py_ssize_t first_live(Frame *f, int64_t window) noexcept nogil:
    """store._FrameCache.first: the oldest sample within the window of the newest."""
    cdef int64_t oldest = f.samples[f.end - 1].stamp - window
    if f.samples[f.start].stamp >= oldest:
        return f.start
    return bisect_left(f, oldest)
