# cython: language_level=3, boundscheck=False, wraparound=False, cdivision=True
# cython: initializedcheck=False
"""The native lane of a streamed pose: its serialized message in, its TRANSFORM written to
every client's socket, all without the interpreter (the stream reader calls `PoseLane`'s
handler with the interpreter's lock released).

Why it exists: at 1 kHz the interpreter's time per pose (cold caches after every wait) is
several times what its conversion needs; bench/bench_pose_path.py measures both paths.

The Python path stays the reference, and this file follows it step by step:
- reading: bridge/codecs/cdr.py (`read_pose`, `read_pose_stamped`, `read_transform_stamped`);
- numbers: protocol/conversions.py (`pose_to_igtl12`, `igtl_stamp_or_now`), the same
  operations in the same order, compiled with -ffp-contract=off, so the floats are the same
  to the bit;
- bytes: protocol/framing.py (`StreamTemplate.encode`) and protocol/crc64.py;
- time: protocol/freshness.py (`daemon_clock_ms`), bridge/core/stream_health.py
  (`Arrivals.note`).
tests/bridge/test_native_stream.py runs both on the same messages and compares the bytes;
tests/bridge/test_native_coverage.py runs it on a build of this file with line tracing and
requires the rules copied here to have run (`make coverage-native` lists the lines that did
not).

Each lane writes to the fanout's clients, or to its own subset of them (`PoseLane.set_slots`:
a device that goes only to its audience, docs/security.md "Who owns a bridge"), so a stream
limited to some clients stays here.

A message this lane does not take as it is (another frame id than its template's, a NaN,
a number that is not finite as float32 once in mm, bytes it cannot read, a client of its
that is not writable at once, a bound on the device, values waiting for the loop) goes to
the Python path, which decides; so does the rest of its batch, so order is kept.

Locks: `Fanout` (one per hub) guards the client list and `hold`; each `Slot` (one per
client) guards its socket. The order is always fanout, then slot; the interpreter's lock is
never taken while either is held, and Python waits for them with it released.
"""

from cpython.buffer cimport PyBUF_SIMPLE, PyBuffer_Release, PyObject_GetBuffer
from cpython.bytes cimport PyBytes_AS_STRING, PyBytes_FromStringAndSize, PyBytes_GET_SIZE
from cpython.pycapsule cimport PyCapsule_New
from libc.errno cimport EAGAIN, EINTR, errno
from libc.math cimport isfinite
from libc.stdint cimport int32_t, int64_t, uint8_t, uint16_t, uint32_t, uint64_t
from libc.stdlib cimport calloc, free, malloc, realloc
from libc.string cimport memcmp, memcpy, memset
from posix.time cimport CLOCK_MONOTONIC, CLOCK_REALTIME, clock_gettime, timespec
from posix.uio cimport iovec

from protocol.conversions import FLOAT32_BOUND

# Bump with the wrappers' expectation (bridge/core/native_stream.py): an older build is
# not used.
INTERFACE = 6

# The one rule for a number sent as float32 is protocol/conversions.py's `fits_float32`:
# its bound, taken from there, not copied.
cdef double _FLOAT32_BOUND = FLOAT32_BOUND

cdef enum:
    # What a lane's handler returns to the reader.
    C_HANDLED = 0
    C_TO_PYTHON = 1
    C_HANDLED_SETTLE = 2  # handled; Python settles what it left (`PoseLane.settle`)
    C_BUSY = 3  # nothing done: another thread held a lock (`try_handle` only)
    # Kinds of pose message (bridge/codecs/cdr.py's readers).
    C_POSE = 0
    C_POSE_STAMPED = 1
    C_TRANSFORM_STAMPED = 2
    # What a write did.
    C_SENT = 0
    C_STASHED = 1  # part was sent; the rest waits in the slot (`take_stash`)
    C_REFUSED = 2  # nothing was sent: the socket is full (or the slot closed)
    C_BROKEN = 3  # the socket failed: the loop's transport meets the same error
    # OpenIGTLink sizes.
    HEADER_SIZE = 58
    EXT_HEADER_SIZE = 12
    CONTENT_SIZE = 48  # a TRANSFORM's 12 float32
    MAX_PARTS = 8  # a frame written from parts (`Slot.send`): header, content, metadata

HANDLED, TO_PYTHON, HANDLED_SETTLE, BUSY = C_HANDLED, C_TO_PYTHON, C_HANDLED_SETTLE, C_BUSY
POSE, POSE_STAMPED, TRANSFORM_STAMPED = C_POSE, C_POSE_STAMPED, C_TRANSFORM_STAMPED
SENT, STASHED, REFUSED, BROKEN = C_SENT, C_STASHED, C_REFUSED, C_BROKEN


cdef extern from "<pthread.h>" nogil:
    ctypedef struct pthread_mutex_t:
        pass
    int pthread_mutex_init(pthread_mutex_t *mutex, void *attr)
    int pthread_mutex_destroy(pthread_mutex_t *mutex)
    int pthread_mutex_lock(pthread_mutex_t *mutex)
    int pthread_mutex_trylock(pthread_mutex_t *mutex)
    int pthread_mutex_unlock(pthread_mutex_t *mutex)


cdef extern from "<sys/socket.h>" nogil:
    cdef struct msghdr:
        iovec *msg_iov
        size_t msg_iovlen
    ssize_t sendmsg(int fd, const msghdr *msg, int flags)
    enum:
        MSG_DONTWAIT
        MSG_NOSIGNAL


# One system call for a message's writes to every client, where io_uring is there
# (bridge/core/send_batch.h says why).
cdef extern from "send_batch.h" nogil:
    ctypedef struct send_batch_t:
        int ring_fd
    int send_batch_open(send_batch_t *b)
    void send_batch_close(send_batch_t *b)
    int send_batch_run(send_batch_t *b, int count, const int *fds, msghdr *messages,
                       int *results)


# --- CRC-64 as OpenIGTLink uses it (protocol/crc64.py: ECMA-182, init 0, no reflection) ---
cdef uint64_t CRC_TABLE[256]


cdef void _crc_table(uint64_t poly) noexcept:
    cdef uint64_t reg
    cdef int v, bit
    for v in range(256):
        reg = (<uint64_t>v) << 56
        for bit in range(8):
            if reg & (<uint64_t>1 << 63):
                reg = (reg << 1) ^ poly
            else:
                reg = reg << 1
        CRC_TABLE[v] = reg


cdef inline uint64_t _crc64(const uint8_t *data, size_t n) noexcept nogil:
    cdef uint64_t crc = 0
    cdef size_t i
    for i in range(n):
        crc = (crc << 8) ^ CRC_TABLE[((crc >> 56) ^ data[i]) & 0xFF]
    return crc


def crc64(bytes data):
    """This module's CRC of ``data`` (tests compare it with protocol/crc64.py's)."""
    return _crc64(<const uint8_t *>PyBytes_AS_STRING(data), <size_t>PyBytes_GET_SIZE(data))


# --- big-endian packing -------------------------------------------------------------------
cdef inline void _put_u16(uint8_t *p, uint16_t v) noexcept nogil:
    p[0] = <uint8_t>(v >> 8)
    p[1] = <uint8_t>v


cdef inline void _put_u32(uint8_t *p, uint32_t v) noexcept nogil:
    p[0] = <uint8_t>(v >> 24)
    p[1] = <uint8_t>(v >> 16)
    p[2] = <uint8_t>(v >> 8)
    p[3] = <uint8_t>v


cdef inline void _put_u64(uint8_t *p, uint64_t v) noexcept nogil:
    _put_u32(p, <uint32_t>(v >> 32))
    _put_u32(p + 4, <uint32_t>v)


cdef inline void _put_f32(uint8_t *p, float v) noexcept nogil:
    cdef uint32_t bits
    memcpy(&bits, &v, 4)
    _put_u32(p, bits)


# --- little-endian CDR reading (the machine's order: `Fanout` refuses big-endian ones) -----
cdef inline uint32_t _u32_le(const uint8_t *p) noexcept nogil:
    return (<uint32_t>p[0]) | (<uint32_t>p[1] << 8) | (<uint32_t>p[2] << 16) | (<uint32_t>p[3] << 24)


cdef inline double _f64_le(const uint8_t *p) noexcept nogil:
    cdef double v
    memcpy(&v, p, 8)
    return v


cdef inline size_t _align8(size_t offset) noexcept nogil:
    # Alignment counts from the end of the 4-byte encapsulation header (cdr.py's _align8).
    return offset + ((8 - ((offset - 4) & 7)) & 7)


cdef inline size_t _align4(size_t offset) noexcept nogil:
    return offset + ((4 - ((offset - 4) & 3)) & 3)


cdef inline int64_t _now_ns(int clock) noexcept nogil:
    cdef timespec now
    clock_gettime(clock, &now)
    return <int64_t>now.tv_sec * 1000000000 + now.tv_nsec


cdef inline uint64_t _igtl_timestamp(uint64_t sec, uint64_t nanosec) noexcept nogil:
    # protocol/conversions.py's _igtl_timestamp: the fraction rounded to nearest.
    return (sec << 32) | ((nanosec * (<uint64_t>1 << 32) + 500000000) // 1000000000)


cdef inline uint64_t _stamp_or_now(int64_t sec, int64_t nanosec) noexcept nogil:
    # protocol/conversions.py's igtl_stamp_or_now.
    cdef int64_t now
    if 0 < sec <= <int64_t>0xFFFFFFFF and 0 <= nanosec < 1000000000:
        return _igtl_timestamp(<uint64_t>sec, <uint64_t>nanosec)
    now = _now_ns(CLOCK_REALTIME)
    return _igtl_timestamp(<uint64_t>(now // 1000000000), <uint64_t>(now % 1000000000))


# --- clients ---------------------------------------------------------------------------------
cdef struct SlotState:
    pthread_mutex_t lock
    int fd  # a descriptor of the client's socket (the session's own dup); -1: none
    int header_version
    bint open
    bint missed  # a lane could not write to it: Python hands that value over
    uint8_t *stash  # the rest of a frame written in part
    size_t stash_size
    unsigned long long sent


cdef int _send(SlotState *slot, const uint8_t *data, size_t n) noexcept nogil:
    cdef iovec part
    part.iov_base = <void *>data
    part.iov_len = n
    return _send_parts(slot, &part, 1, n)


cdef inline bint _writable(SlotState *slot) noexcept nogil:
    """Whether a frame may be written to the slot now (held); closes it if not."""
    if slot.fd < 0 or slot.stash != NULL:
        slot.open = False
        return False
    return True


cdef int _send_parts(SlotState *slot, iovec *parts, int count, size_t n) noexcept nogil:
    """Write a whole frame (``count`` parts, ``n`` bytes) now or keep its rest; the slot is
    held. A slot that could not take it whole is closed."""
    cdef ssize_t sent
    cdef msghdr message
    if not _writable(slot):
        return C_REFUSED
    memset(&message, 0, sizeof(message))
    message.msg_iov = parts
    message.msg_iovlen = <size_t>count
    while True:
        sent = sendmsg(slot.fd, &message, MSG_DONTWAIT | MSG_NOSIGNAL)
        if sent >= 0 or errno != EINTR:
            break
    return _settle(slot, parts, count, n, sent, errno if sent < 0 else 0)


cdef int _settle(SlotState *slot, iovec *parts, int count, size_t n, ssize_t sent,
                 int error) noexcept nogil:
    """What a write of ``sent`` bytes (negative: it failed with ``error``) of a frame left:
    SENT, or the slot closed and its rest kept (STASHED), or nothing sent."""
    cdef size_t skip, at, take
    cdef int i
    if sent == <ssize_t>n:
        slot.sent += 1
        return C_SENT
    slot.open = False
    if sent > 0:
        slot.stash = <uint8_t *>malloc(n - <size_t>sent)
        if slot.stash == NULL:  # the rest cannot be kept: the stream would be corrupt
            return C_BROKEN
        skip = <size_t>sent
        at = 0
        for i in range(count):
            if skip >= parts[i].iov_len:
                skip -= parts[i].iov_len
                continue
            take = parts[i].iov_len - skip
            memcpy(slot.stash + at, <uint8_t *>parts[i].iov_base + skip, take)
            at += take
            skip = 0
        slot.stash_size = n - <size_t>sent
        slot.sent += 1
        return C_STASHED
    if sent == 0 or error == EAGAIN:  # EWOULDBLOCK is EAGAIN on Linux
        return C_REFUSED
    return C_BROKEN


def _contiguous(parts):
    """The parts as buffers the kernel can read in one piece each (a strided view is
    copied; the usual parts, bytes and contiguous views, are not)."""
    return tuple([part if memoryview(part).c_contiguous else memoryview(part).tobytes()
                  for part in parts])


cdef class _Held:
    """``with it:`` holds its mutex, waiting with the interpreter's lock released."""

    cdef pthread_mutex_t *_mutex

    def __enter__(self):
        with nogil:
            pthread_mutex_lock(self._mutex)
        return self

    def __exit__(self, *exc):
        pthread_mutex_unlock(self._mutex)
        return False


cdef class Slot(_Held):
    """One client's socket as the native lanes see it. Its session holds it (``with
    slot:``) around each write of its own, closes it (``open = False``) before anything of
    the client may wait elsewhere, and opens it only when nothing does. A lane writes only
    to open slots, and closes one that did not take a frame whole."""

    cdef SlotState *state
    cdef public object owner  # a weak reference to the session
    cdef object _sock  # the socket whose descriptor `fd` is

    def __cinit__(self, owner=None):
        self.state = <SlotState *>malloc(sizeof(SlotState))
        if self.state == NULL:
            raise MemoryError()
        pthread_mutex_init(&self.state.lock, NULL)
        self._mutex = &self.state.lock
        self.state.fd = -1
        self.state.header_version = 1
        self.state.open = False
        self.state.missed = False
        self.state.stash = NULL
        self.state.stash_size = 0
        self.state.sent = 0
        self.owner = owner

    def __dealloc__(self):
        if self.state != NULL:
            free(self.state.stash)
            pthread_mutex_destroy(&self.state.lock)
            free(self.state)
            self.state = NULL

    # The rest is called while holding the slot.
    def connect(self, sock):
        """Write to ``sock`` (a non-blocking socket the caller closes after `disconnect`)."""
        self.state.fd = sock.fileno()
        self._sock = sock

    def disconnect(self):
        """No more writes: the socket is about to be closed."""
        self.state.fd = -1
        self.state.open = False
        self._sock = None

    @property
    def fd(self):
        return self.state.fd

    @property
    def header_version(self):
        return self.state.header_version

    @header_version.setter
    def header_version(self, int value):
        self.state.header_version = value

    @property
    def open(self):
        return self.state.open

    @open.setter
    def open(self, bint value):
        self.state.open = value

    @property
    def sent(self):
        """Frames written whole, or in part with the rest kept (by a lane or `send`)."""
        return self.state.sent

    @property
    def has_stash(self):
        return self.state.stash != NULL

    def take_stash(self):
        """The rest of a frame written in part, which goes before anything else; None."""
        if self.state.stash == NULL:
            return None
        data = PyBytes_FromStringAndSize(<char *>self.state.stash,
                                         <Py_ssize_t>self.state.stash_size)
        free(self.state.stash)
        self.state.stash = NULL
        self.state.stash_size = 0
        return data

    def send(self, data):
        """Write a frame now as a lane does: SENT, STASHED, REFUSED or BROKEN. ``data``: its
        bytes, or a tuple of contiguous buffers written as one frame (an image's header,
        pixels where they lie, metadata), without joining them."""
        cdef const uint8_t *p
        cdef size_t n = 0
        cdef int result, count, i, held = 0
        cdef Py_buffer views[MAX_PARTS]
        cdef iovec parts[MAX_PARTS]
        if type(data) is bytes:
            p = <const uint8_t *>PyBytes_AS_STRING(data)
            n = <size_t>PyBytes_GET_SIZE(data)
            with nogil:
                result = _send(self.state, p, n)
            return result
        count = len(data)
        if not 0 < count <= MAX_PARTS:
            raise ValueError(f"expected 1 to {MAX_PARTS} parts, got {count}")
        data = _contiguous(data)
        try:
            for i in range(count):
                PyObject_GetBuffer(data[i], &views[i], PyBUF_SIMPLE)
                held += 1
                parts[i].iov_base = views[i].buf
                parts[i].iov_len = <size_t>views[i].len
                n += <size_t>views[i].len
            with nogil:
                result = _send_parts(self.state, parts, count, n)
        finally:
            for i in range(held):
                PyBuffer_Release(&views[i])
        return result

    def take_missed(self):
        """Whether a lane skipped this client since the last call."""
        missed = self.state.missed
        self.state.missed = False
        return missed


cdef struct FanoutState:
    pthread_mutex_t lock
    bint hold
    SlotState **slots
    Py_ssize_t count
    Py_ssize_t room  # writes a batch has room for (`_room`)
    int64_t clock_modulus
    send_batch_t batch  # ring_fd -1: one write at a time
    # Per client, for a batch: what is written where, and what each write did.
    int *fds
    Py_ssize_t *staged  # the slot of each write
    iovec *parts
    msghdr *messages
    int *sent


cdef inline int64_t _clock_ms(FanoutState *fanout) noexcept nogil:
    # protocol/freshness.py's daemon_clock_ms: monotonic ms, never 0.
    return (_now_ns(CLOCK_MONOTONIC) // 1000000) % (fanout.clock_modulus - 1) + 1


cdef class Fanout(_Held):
    """The clients every native lane writes to (one per hub). ``with fanout:`` holds it, and
    no lane writes meanwhile. `hold` (set while values wait for the loop) sends every
    message to the Python path, so that nothing passes them."""

    cdef FanoutState *state
    cdef list _slots

    def __cinit__(self, long long clock_modulus, bint batch=True):
        import sys
        if sys.byteorder != "little":
            raise RuntimeError("the native lane reads CDR as a little-endian machine")
        if clock_modulus < 2:
            raise ValueError(f"clock_modulus: expected 2 or more, got {clock_modulus}")
        self.state = <FanoutState *>malloc(sizeof(FanoutState))
        if self.state == NULL:
            raise MemoryError()
        pthread_mutex_init(&self.state.lock, NULL)
        self._mutex = &self.state.lock
        self.state.hold = False
        self.state.slots = NULL
        self.state.count = 0
        self.state.room = 0
        self.state.clock_modulus = clock_modulus
        self.state.fds = NULL
        self.state.staged = NULL
        self.state.parts = NULL
        self.state.messages = NULL
        self.state.sent = NULL
        self.state.batch.ring_fd = -1
        if batch:
            send_batch_open(&self.state.batch)  # else, or if it fails: one at a time
        self._slots = []

    def __dealloc__(self):
        if self.state != NULL:
            send_batch_close(&self.state.batch)
            free(self.state.slots)
            free(self.state.fds)
            free(self.state.staged)
            free(self.state.parts)
            free(self.state.messages)
            free(self.state.sent)
            pthread_mutex_destroy(&self.state.lock)
            free(self.state)
            self.state = NULL

    @property
    def hold(self):
        return self.state.hold

    @hold.setter
    def hold(self, bint value):  # set while holding the fanout
        self.state.hold = value

    @property
    def batched(self):
        """Whether a message's writes to every client go in one system call (io_uring)."""
        return self.state.batch.ring_fd >= 0

    @property
    def slots(self):
        return list(self._slots)

    def set_slots(self, slots):
        """The clients from now on. Call while holding the fanout."""
        kept = [<Slot?>s for s in slots]
        cdef Py_ssize_t n = len(kept)
        cdef Py_ssize_t i
        _grow(<void **>&self.state.slots, <size_t>max(n, 1) * sizeof(SlotState *))
        _room(self.state, n)
        cdef SlotState **array = self.state.slots
        for i in range(n):
            array[i] = (<Slot>kept[i]).state
        self._slots = kept
        self.state.count = n


cdef int _room(FanoutState *fanout, Py_ssize_t n) except -1:
    """A batch's room for ``n`` writes (a write per client of a lane)."""
    if n <= fanout.room:
        return 0
    cdef size_t room = <size_t>n
    _grow(<void **>&fanout.fds, room * sizeof(int))
    _grow(<void **>&fanout.staged, room * sizeof(Py_ssize_t))
    _grow(<void **>&fanout.parts, room * sizeof(iovec))
    _grow(<void **>&fanout.messages, room * sizeof(msghdr))
    _grow(<void **>&fanout.sent, room * sizeof(int))
    fanout.room = n
    return 0


cdef int _grow(void **pointer, size_t size) except -1:
    """Resize ``*pointer``'s block to ``size`` bytes; MemoryError leaves it as it was."""
    cdef void *grown = realloc(pointer[0], size)
    if grown == NULL:
        raise MemoryError()
    pointer[0] = grown
    return 0


# --- a pose stream ----------------------------------------------------------------------------
cdef struct LaneState:
    FanoutState *fanout
    int kind
    bint enabled
    # Its own clients (`PoseLane.set_slots`), or (own_slots false) the fanout's.
    bint own_slots
    SlotState **slots
    Py_ssize_t slot_count
    bint settle  # a slot was missed or stashed: Python settles before the next native one
    # The template: the frame ids it is for (as CDR holds them) and StreamTemplate's parts.
    bint has_template
    uint8_t *frame_raw
    size_t frame_size
    uint8_t *child_raw
    size_t child_size
    uint8_t type_raw[12]
    uint8_t name_raw[20]
    uint16_t meta_header_size
    uint32_t meta_size
    uint8_t *buffer  # the v2 frame (metadata in place), then the v1 frame
    # What the Python side reads, holding the fanout.
    unsigned long long count
    uint8_t *last  # the last message written here, as it came
    size_t last_size
    size_t last_capacity
    size_t last_max
    bint has_last
    bint has_latest
    uint8_t latest_content[CONTENT_SIZE]
    double latest_values[12]
    uint64_t latest_timestamp
    int64_t latest_clock
    bint has_arrival
    bint has_period
    double arrival_last
    double arrival_period
    unsigned long long arrival_count
    double smoothing


cdef struct Handler:
    # What the stream reader calls for each message, without the interpreter's lock.
    int (*handle)(void *lane, const uint8_t *data, size_t size) noexcept nogil
    void *lane
    # The same, but BUSY instead of waiting for a lock: for a middleware thread, which
    # holds the middleware's locks, while a lock here may be held by a thread that needs
    # the interpreter, which a thread needing those may hold.
    int (*try_handle)(void *lane, const uint8_t *data, size_t size) noexcept nogil


cdef inline SlotState **_slots_of(LaneState *lane, Py_ssize_t *count) noexcept nogil:
    """The clients ``lane`` writes to: its own subset, or every client of its fanout."""
    if lane.own_slots:
        count[0] = lane.slot_count
        return lane.slots
    count[0] = lane.fanout.count
    return lane.fanout.slots


cdef inline size_t _v1_offset(LaneState *lane) noexcept nogil:
    return HEADER_SIZE + EXT_HEADER_SIZE + CONTENT_SIZE + lane.meta_header_size + lane.meta_size


cdef void _note(LaneState *lane, double now) noexcept nogil:
    # bridge/core/stream_health.py's Arrivals.note, the same formula.
    cdef double gap
    if lane.has_arrival:
        gap = now - lane.arrival_last
        if lane.has_period:
            lane.arrival_period = lane.arrival_period + lane.smoothing * (gap - lane.arrival_period)
        else:
            lane.arrival_period = gap
            lane.has_period = True
    lane.arrival_last = now
    lane.has_arrival = True
    lane.arrival_count += 1


cdef int _convert(LaneState *lane, const uint8_t *data, size_t n, uint8_t *content,
                  double *values, uint64_t *timestamp) noexcept nogil:
    """0 with the content, the 12 numbers and the time stamp; -1: the Python path's."""
    cdef int64_t sec = -1, nanosec = 0
    cdef size_t offset, length
    cdef size_t frame_at = 0, frame_size = 0, child_at = 0, child_size = 0
    cdef double tx, ty, tz, x, y, z, w, norm2, s
    cdef double xx, yy, zz, xy, xz, yz, wx, wy, wz
    cdef int i
    if not lane.has_template or n < 4 or data[0] != 0 or data[1] != 1:
        return -1
    if lane.kind == C_POSE:
        offset = 4
    else:
        if n < 16:
            return -1
        sec = <int32_t>_u32_le(data + 4)
        if lane.kind == C_POSE_STAMPED:
            nanosec = <int32_t>_u32_le(data + 8)  # cdr.py reads it signed ("<iiI")
        else:
            nanosec = _u32_le(data + 8)  # unsigned there ("<iI")
        length = _u32_le(data + 12)
        if length == 0 or length > n - 16:
            return -1
        frame_at, frame_size = 16, length - 1
        if lane.kind == C_POSE_STAMPED:
            offset = _align8(16 + length)
        else:
            offset = _align4(16 + length)
            if offset + 4 > n:
                return -1
            length = _u32_le(data + offset)
            if length == 0 or length > n - offset - 4:
                return -1
            child_at, child_size = offset + 4, length - 1
            offset = _align8(offset + 4 + length)
    if offset + 56 > n:
        return -1
    # Other frame ids: the Python path checks them (UTF-8) and sets this lane's template.
    if frame_size != lane.frame_size or child_size != lane.child_size:
        return -1
    if frame_size and memcmp(data + frame_at, lane.frame_raw, frame_size) != 0:
        return -1
    if child_size and memcmp(data + child_at, lane.child_raw, child_size) != 0:
        return -1
    tx = _f64_le(data + offset)
    ty = _f64_le(data + offset + 8)
    tz = _f64_le(data + offset + 16)
    x = _f64_le(data + offset + 24)
    y = _f64_le(data + offset + 32)
    z = _f64_le(data + offset + 40)
    w = _f64_le(data + offset + 48)
    # protocol/conversions.py's pose_to_igtl12, operation for operation (the translation
    # is judged with the rest below).
    norm2 = x * x + y * y + z * z + w * w
    if not isfinite(norm2) or norm2 < 1e-24:
        return -1
    s = 2.0 / norm2
    xx = x * x * s
    yy = y * y * s
    zz = z * z * s
    xy = x * y * s
    xz = x * z * s
    yz = y * z * s
    wx = w * x * s
    wy = w * y * s
    wz = w * z * s
    values[0] = 1.0 - (yy + zz)
    values[1] = xy + wz
    values[2] = xz - wy
    values[3] = xy - wz
    values[4] = 1.0 - (xx + zz)
    values[5] = yz + wx
    values[6] = xz + wy
    values[7] = yz - wx
    values[8] = 1.0 - (xx + yy)
    values[9] = tx * 1000.0  # MM_PER_M
    values[10] = ty * 1000.0
    values[11] = tz * 1000.0
    for i in range(12):  # fits_float32, with its bound: the Python path says why not
        if not (-_FLOAT32_BOUND < values[i] < _FLOAT32_BOUND):
            return -1
        _put_f32(content + 4 * i, <float>values[i])
    timestamp[0] = _stamp_or_now(sec, nanosec)
    return 0


cdef size_t _frame(LaneState *lane, int header_version, const uint8_t *content,
                   uint64_t timestamp, int64_t clock) noexcept nogil:
    """Pack the frame for ``header_version`` in the buffer (v2 at 0, v1 at `_v1_offset`)
    as StreamTemplate.encode does; its size."""
    cdef uint8_t *p
    cdef size_t body
    if header_version == 2:
        p = lane.buffer
        body = EXT_HEADER_SIZE + CONTENT_SIZE + lane.meta_header_size + lane.meta_size
        _put_u32(p + HEADER_SIZE + 8, <uint32_t>clock)  # the rest of it is set once
        memcpy(p + HEADER_SIZE + EXT_HEADER_SIZE, content, CONTENT_SIZE)
    else:
        p = lane.buffer + _v1_offset(lane)
        body = CONTENT_SIZE
        memcpy(p + HEADER_SIZE, content, CONTENT_SIZE)
    _put_u16(p, <uint16_t>header_version)
    memcpy(p + 2, lane.type_raw, 12)
    memcpy(p + 14, lane.name_raw, 20)
    _put_u64(p + 34, timestamp)
    _put_u64(p + 42, body)
    _put_u64(p + 50, _crc64(p + HEADER_SIZE, body))
    return HEADER_SIZE + body


cdef void _keep(LaneState *lane, const uint8_t *data, size_t n, const uint8_t *content,
                const double *values, uint64_t timestamp, int64_t clock) noexcept nogil:
    cdef uint8_t *grown
    lane.count += 1
    lane.has_last = False
    if n <= lane.last_max:
        if n > lane.last_capacity:
            grown = <uint8_t *>realloc(lane.last, n)
            if grown != NULL:
                lane.last = grown
                lane.last_capacity = n
        if n <= lane.last_capacity:
            memcpy(lane.last, data, n)
            lane.last_size = n
            lane.has_last = True
    memcpy(lane.latest_content, content, CONTENT_SIZE)
    memcpy(lane.latest_values, values, 12 * sizeof(double))
    lane.latest_timestamp = timestamp
    lane.latest_clock = clock
    lane.has_latest = True


cdef inline bint _lock(pthread_mutex_t *mutex, bint wait) noexcept nogil:
    if wait:
        pthread_mutex_lock(mutex)
        return True
    return pthread_mutex_trylock(mutex) == 0


cdef bint _write_all(FanoutState *fanout, LaneState *lane, SlotState **slots,
                     Py_ssize_t slot_count, size_t size1, size_t size2) noexcept nogil:
    """The lane's frame to each of its clients (each slot held), in one system call where
    the fanout batches; True when some client did not take it whole (Python settles)."""
    cdef Py_ssize_t i, j, count = 0
    cdef SlotState *slot
    cdef iovec part
    cdef int result
    cdef bint settle = False
    cdef bint batched = fanout.batch.ring_fd >= 0 and slot_count > 1
    for i in range(slot_count):
        slot = slots[i]
        if slot.header_version == 2:
            part.iov_base = <void *>lane.buffer
            part.iov_len = size2
        else:
            part.iov_base = <void *>(lane.buffer + _v1_offset(lane))
            part.iov_len = size1
        if not slot.open:  # its session closed it meanwhile, for a write of its own
            result = C_REFUSED
        elif not batched:
            result = _send_parts(slot, &part, 1, part.iov_len)
        elif not _writable(slot):
            result = C_REFUSED
        else:
            fanout.fds[count] = slot.fd
            fanout.staged[count] = i
            fanout.parts[count] = part
            memset(&fanout.messages[count], 0, sizeof(msghdr))
            fanout.messages[count].msg_iov = &fanout.parts[count]
            fanout.messages[count].msg_iovlen = 1
            count += 1
            continue
        settle = _missed(slot, result) or settle
    if count:
        if send_batch_run(&fanout.batch, <int>count, fanout.fds, fanout.messages,
                          fanout.sent) != 0:
            send_batch_close(&fanout.batch)  # the ring failed: one at a time from now on
        for j in range(count):
            slot = slots[fanout.staged[j]]
            result = _settle(slot, &fanout.parts[j], 1, fanout.parts[j].iov_len,
                             fanout.sent[j], -fanout.sent[j] if fanout.sent[j] < 0 else 0)
            settle = _missed(slot, result) or settle
    return settle


cdef inline bint _missed(SlotState *slot, int result) noexcept nogil:
    """Whether a write's result leaves Python something to settle; marks a client that
    missed the value."""
    if result == C_REFUSED or result == C_BROKEN:
        slot.missed = True
        return True
    return result == C_STASHED


cdef int _handle(void *lane_pointer, const uint8_t *data, size_t n) noexcept nogil:
    return _handle_as(lane_pointer, data, n, True)


cdef int _try_handle(void *lane_pointer, const uint8_t *data, size_t n) noexcept nogil:
    return _handle_as(lane_pointer, data, n, False)


cdef int _handle_as(void *lane_pointer, const uint8_t *data, size_t n, bint wait) noexcept nogil:
    """One message: written to each of the lane's clients (HANDLED, or HANDLED_SETTLE when
    a client could not take it whole), or TO_PYTHON with nothing done; BUSY with nothing
    done when not ``wait``ing and a lock is held. Every client's slot is held before the
    first write, so a message goes to all or to none."""
    cdef LaneState *lane = <LaneState *>lane_pointer
    cdef FanoutState *fanout = lane.fanout
    cdef SlotState *slot
    cdef SlotState **slots
    cdef Py_ssize_t slot_count
    cdef uint8_t content[CONTENT_SIZE]
    cdef double values[12]
    cdef uint64_t timestamp
    cdef int64_t clock
    cdef Py_ssize_t i, j
    cdef bint v1 = False, v2 = False, settle = False
    cdef size_t size1 = 0, size2 = 0
    if _convert(lane, data, n, content, values, &timestamp) != 0:
        return C_TO_PYTHON
    if not _lock(&fanout.lock, wait):
        return C_BUSY
    if fanout.hold or not lane.enabled or lane.settle:
        pthread_mutex_unlock(&fanout.lock)
        return C_TO_PYTHON
    slots = _slots_of(lane, &slot_count)
    for i in range(slot_count):
        slot = slots[i]
        if not slot.open:
            pthread_mutex_unlock(&fanout.lock)
            return C_TO_PYTHON
        if slot.header_version == 2:
            v2 = True
        else:
            v1 = True
    for i in range(slot_count):
        if not _lock(&slots[i].lock, wait):
            for j in range(i):
                pthread_mutex_unlock(&slots[j].lock)
            pthread_mutex_unlock(&fanout.lock)
            return C_BUSY
    clock = _clock_ms(fanout)
    if v2:
        size2 = _frame(lane, 2, content, timestamp, clock)
    if v1:
        size1 = _frame(lane, 1, content, timestamp, clock)
    settle = _write_all(fanout, lane, slots, slot_count, size1, size2)
    for i in range(slot_count):
        pthread_mutex_unlock(&slots[i].lock)
    _keep(lane, data, n, content, values, timestamp, clock)
    _note(lane, <double>_now_ns(CLOCK_MONOTONIC) / 1e9)
    lane.settle = settle
    pthread_mutex_unlock(&fanout.lock)
    return C_HANDLED_SETTLE if settle else C_HANDLED


cdef class PoseLane:
    """One streamed Pose / PoseStamped / TransformStamped topic's native lane (`handler`
    goes to the stream reader). Off (`enabled`) until its owner says it may write."""

    cdef LaneState *state
    cdef Handler _handler
    cdef Fanout _fanout
    cdef object _capsule
    cdef list _slots  # its own clients (`set_slots`), or None: the fanout's

    def __cinit__(self, Fanout fanout, int kind, size_t last_max_bytes, double smoothing):
        if kind not in (C_POSE, C_POSE_STAMPED, C_TRANSFORM_STAMPED):
            raise ValueError(f"kind: expected POSE, POSE_STAMPED or TRANSFORM_STAMPED, "
                             f"got {kind}")
        self.state = <LaneState *>calloc(1, sizeof(LaneState))
        if self.state == NULL:
            raise MemoryError()
        self._fanout = fanout
        self.state.fanout = fanout.state
        self.state.kind = kind
        self.state.last_max = last_max_bytes
        self.state.smoothing = smoothing
        self._handler.handle = _handle
        self._handler.try_handle = _try_handle
        self._handler.lane = <void *>self.state
        self._capsule = PyCapsule_New(<void *>&self._handler, _HANDLER_CAPSULE, NULL)

    def __dealloc__(self):
        if self.state != NULL:
            free(self.state.buffer)
            free(self.state.last)
            free(self.state.frame_raw)
            free(self.state.child_raw)
            free(self.state.slots)
            free(self.state)
            self.state = NULL

    @property
    def handler(self):
        """The capsule the stream reader calls; valid while this lane lives."""
        return self._capsule

    # The rest is called while holding the fanout.
    @property
    def enabled(self):
        return self.state.enabled

    @enabled.setter
    def enabled(self, bint value):
        self.state.enabled = value

    @property
    def count(self):
        """Messages written here."""
        return self.state.count

    @property
    def slots(self):
        """The clients it writes to: its own (`set_slots`), else None (the fanout's)."""
        return None if self._slots is None else list(self._slots)

    def set_slots(self, slots):
        """Write to ``slots`` only from now on (a device limited to an audience: a subset
        of the fanout's clients, perhaps none), or, with None, to every client of the
        fanout."""
        if slots is None:
            self.state.own_slots = False
            self._slots = None
            return
        kept = [<Slot?>s for s in slots]
        cdef Py_ssize_t n = len(kept)
        cdef Py_ssize_t i
        _grow(<void **>&self.state.slots, <size_t>max(n, 1) * sizeof(SlotState *))
        _room(self._fanout.state, n)
        for i in range(n):
            self.state.slots[i] = (<Slot>kept[i]).state
        self.state.slot_count = n
        self.state.own_slots = True
        self._slots = kept

    def set_template(self, bytes frame_raw, bytes child_raw, bytes type_raw, bytes name_raw,
                     int meta_header_size, long long meta_size, bytes meta_tail):
        """The frame ids this lane takes (their UTF-8, as CDR has them without the
        terminator) and their `StreamTemplate`'s packed parts (`wire_parts`)."""
        if len(type_raw) > 12 or len(name_raw) > 20:
            raise ValueError(f"type_raw and name_raw: expected at most 12 and 20 bytes, got "
                             f"{len(type_raw)} and {len(name_raw)}")
        if not (0 <= meta_header_size <= 0xFFFF and 0 <= meta_size <= 0xFFFFFFFF
                and meta_header_size + meta_size == len(meta_tail)):
            raise ValueError(f"metadata sizes: expected those of meta_tail "
                             f"({len(meta_tail)} bytes), got {meta_header_size} + {meta_size}")
        cdef size_t size = 2 * HEADER_SIZE + EXT_HEADER_SIZE + 2 * CONTENT_SIZE + len(meta_tail)
        cdef LaneState *lane = self.state
        cdef uint8_t *buffer = <uint8_t *>malloc(size)
        cdef uint8_t *frame = _copy(frame_raw)
        cdef uint8_t *child = _copy(child_raw)
        if buffer == NULL or frame == NULL or child == NULL:
            free(buffer)
            free(frame)
            free(child)
            raise MemoryError()
        free(lane.buffer)
        free(lane.frame_raw)
        free(lane.child_raw)
        lane.buffer = buffer
        lane.frame_raw, lane.frame_size = frame, len(frame_raw)
        lane.child_raw, lane.child_size = child, len(child_raw)
        memset(lane.type_raw, 0, 12)  # struct's "12s" and "20s" pad with zeros
        memset(lane.name_raw, 0, 20)
        memcpy(lane.type_raw, PyBytes_AS_STRING(type_raw), len(type_raw))
        memcpy(lane.name_raw, PyBytes_AS_STRING(name_raw), len(name_raw))
        lane.meta_header_size = <uint16_t>meta_header_size
        lane.meta_size = <uint32_t>meta_size
        # The v2 extended header and metadata never change: packed once.
        _put_u16(buffer + HEADER_SIZE, EXT_HEADER_SIZE)
        _put_u16(buffer + HEADER_SIZE + 2, lane.meta_header_size)
        _put_u32(buffer + HEADER_SIZE + 4, lane.meta_size)
        if len(meta_tail):
            memcpy(buffer + HEADER_SIZE + EXT_HEADER_SIZE + CONTENT_SIZE,
                   PyBytes_AS_STRING(meta_tail), len(meta_tail))
        lane.has_template = True

    def frame_ids(self):
        """The template's frame ids (raw bytes, as `set_template` had them), or None."""
        if not self.state.has_template:
            return None
        return (PyBytes_FromStringAndSize(<char *>self.state.frame_raw,
                                          <Py_ssize_t>self.state.frame_size),
                PyBytes_FromStringAndSize(<char *>self.state.child_raw,
                                          <Py_ssize_t>self.state.child_size))

    def last(self):
        """The last message written here (bytes), or None."""
        if not self.state.has_last:
            return None
        return PyBytes_FromStringAndSize(<char *>self.state.last,
                                         <Py_ssize_t>self.state.last_size)

    def latest(self):
        """``(content, timestamp, clock, values)`` of the last value written here, or None."""
        if not self.state.has_latest:
            return None
        return (PyBytes_FromStringAndSize(<char *>self.state.latest_content, CONTENT_SIZE),
                self.state.latest_timestamp, self.state.latest_clock,
                tuple([self.state.latest_values[i] for i in range(12)]))

    def forget(self):
        """The Python path took a later message: the last and latest values are its own."""
        self.state.has_last = False
        self.state.has_latest = False

    def arrivals(self):
        """``(last, period, count)`` of every message noted, as `Arrivals` keeps them."""
        lane = self.state
        return (lane.arrival_last if lane.has_arrival else None,
                lane.arrival_period if lane.has_period else None, lane.arrival_count)

    def note(self, double now):
        """`Arrivals.note` for a message the Python path took."""
        _note(self.state, now)

    def settle(self):
        """The owners (as the slots have them: weak references to sessions) of the slots
        that missed the last value written here (they hand it over) and of those that kept
        the rest of a frame (their loop writes it); the lane writes again after this."""
        missed = []
        stashed = []
        for slot in (self._fanout._slots if self._slots is None else self._slots):
            if (<Slot>slot).state.missed:
                (<Slot>slot).state.missed = False
                missed.append((<Slot>slot).owner)
            elif (<Slot>slot).state.stash != NULL:
                stashed.append((<Slot>slot).owner)
        self.state.settle = False
        return missed, stashed

    # For the tests, which compare with the Python path.
    def handle(self, bytes data, bint wait=True):
        """What the reader does with ``data``: HANDLED, TO_PYTHON or HANDLED_SETTLE (or
        BUSY, not ``wait``ing: what a middleware thread does)."""
        cdef const uint8_t *p = <const uint8_t *>PyBytes_AS_STRING(data)
        cdef size_t n = <size_t>PyBytes_GET_SIZE(data)
        cdef int result
        with nogil:
            result = _handle_as(<void *>self.state, p, n, wait)
        return result

    def encode(self, bytes data, int header_version, long long clock):
        """The frame this lane writes for ``data``, or None where the Python path takes
        it."""
        cdef uint8_t content[CONTENT_SIZE]
        cdef double values[12]
        cdef uint64_t timestamp
        cdef size_t size
        if header_version not in (1, 2):
            raise ValueError(f"header_version: expected 1 or 2, got {header_version}")
        if _convert(self.state, <const uint8_t *>PyBytes_AS_STRING(data),
                    <size_t>PyBytes_GET_SIZE(data), content, values, &timestamp) != 0:
            return None
        cdef size_t offset = 0 if header_version == 2 else _v1_offset(self.state)
        size = _frame(self.state, header_version, content, timestamp, clock)
        return PyBytes_FromStringAndSize(<char *>(self.state.buffer + offset), <Py_ssize_t>size)


# The handler capsule's name, which bridge/ros/_rcl_reader.pyx asks for: changed with
# Handler's layout, so a reader built for another never calls it.
cdef const char *_HANDLER_CAPSULE = b"bridge.core.native_stream.Handler3"
HANDLER_CAPSULE = _HANDLER_CAPSULE.decode()


cdef uint8_t *_copy(bytes data) except? NULL:
    cdef size_t n = len(data)
    cdef uint8_t *out = <uint8_t *>malloc(max(n, 1))
    if out != NULL and n:
        memcpy(out, PyBytes_AS_STRING(data), n)
    return out


_crc_table(0x42F0E1EBA9EA3693)  # protocol/crc64.py's POLY
