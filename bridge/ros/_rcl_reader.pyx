# cython: language_level=3
"""Serialized messages of rcl subscriptions, waited for and taken with the interpreter's lock
released.

rclpy takes a raw message holding the lock: a peer's 10 MB TFMessage kept every other
thread of the daemon (the event loop among them) waiting about 20 ms. Here
`rcl_take_serialized_message` runs without it; the caller reads the message from a view on
this reader's buffer, valid until its next `take`.

Waiting: the middleware tells each subscription's new messages through rcl's on-new-message
callback (as rclpy's EventsExecutor has it told), which wakes the reader's thread. A wait
set is not used: Fast DDS wakes one after a message was taken, for nothing, and a reader
that waits again at once spins until it stops.

A subscription with a native handler (a streamed pose) is taken in that callback itself,
on the middleware's thread, while the reader's thread waits: a message then costs no
thread wake. One taker at a time (`take_lock`), and none there while Python holds messages
taken before (`python_has`), so each subscription's messages are handled in order; what a
handler leaves to Python is handed to the reader's thread (`handed`).

Built by setup.py where rcl's headers are found beside the interpreter (ROS 2 from PyPI puts
them under ``sys.prefix/include``); imported only after rclpy, which has loaded the rcl
libraries this module needs. Elsewhere the daemon takes these topics through rclpy.
"""

cimport cython
from cpython.bytes cimport PyBytes_FromStringAndSize
from cpython.memoryview cimport PyMemoryView_FromMemory
from cpython.pycapsule cimport PyCapsule_GetPointer
from cpython.buffer cimport PyBUF_READ
from libc.stdint cimport int64_t, uint8_t
from libc.stdlib cimport calloc, free, malloc
from posix.time cimport CLOCK_MONOTONIC, clock_gettime, timespec

# Bump with `bridge.ros.raw_reader.READER_INTERFACE`: a module from an older build is not used.
INTERFACE = 5


cdef extern from "rcl/rcl.h" nogil:
    ctypedef int rcl_ret_t
    ctypedef struct rcl_allocator_t:
        pass
    ctypedef struct rcl_subscription_t:
        pass
    ctypedef struct rmw_message_info_t:
        pass
    ctypedef struct rmw_subscription_allocation_t:
        pass
    ctypedef struct rcl_serialized_message_t:
        uint8_t *buffer
        size_t buffer_length
    ctypedef void (*rcl_event_callback_t)(const void *user_data, size_t number_of_events)

    enum:
        RCL_RET_OK
        RCL_RET_SUBSCRIPTION_TAKE_FAILED

    rcl_allocator_t rcl_get_default_allocator()
    rcl_ret_t rcl_take_serialized_message(const rcl_subscription_t *subscription,
                                          rcl_serialized_message_t *message,
                                          rmw_message_info_t *info,
                                          rmw_subscription_allocation_t *allocation)
    rcl_ret_t rcl_subscription_set_on_new_message_callback(
        const rcl_subscription_t *subscription, rcl_event_callback_t callback,
        const void *user_data)
    rcl_serialized_message_t rmw_get_zero_initialized_serialized_message()
    rcl_ret_t rmw_serialized_message_init(rcl_serialized_message_t *message, size_t capacity,
                                          const rcl_allocator_t *allocator)
    rcl_ret_t rmw_serialized_message_fini(rcl_serialized_message_t *message)


cdef extern from "rcutils/error_handling.h" nogil:
    void rcutils_reset_error()


cdef extern from "<pthread.h>" nogil:
    ctypedef struct pthread_mutex_t:
        pass
    ctypedef struct pthread_cond_t:
        pass
    ctypedef struct pthread_condattr_t:
        pass
    int pthread_mutex_init(pthread_mutex_t *mutex, void *attr)
    int pthread_mutex_destroy(pthread_mutex_t *mutex)
    int pthread_mutex_lock(pthread_mutex_t *mutex)
    int pthread_mutex_trylock(pthread_mutex_t *mutex)
    int pthread_mutex_unlock(pthread_mutex_t *mutex)
    int pthread_condattr_init(pthread_condattr_t *attr)
    int pthread_condattr_setclock(pthread_condattr_t *attr, int clock)
    int pthread_condattr_destroy(pthread_condattr_t *attr)
    int pthread_cond_init(pthread_cond_t *cond, pthread_condattr_t *attr)
    int pthread_cond_destroy(pthread_cond_t *cond)
    int pthread_cond_signal(pthread_cond_t *cond)
    int pthread_cond_timedwait(pthread_cond_t *cond, pthread_mutex_t *mutex,
                               const timespec *abstime)


class ReaderError(RuntimeError):
    """rcl refused a take or a callback: the reader can go on no further."""


cdef struct _Handler:
    # A native lane (bridge/core/_native_stream.pyx's Handler): called for each message of
    # its subscription without the interpreter's lock; 0 handled, 1 for Python, 2 handled
    # and Python settles after it; `try_handle`: 3, nothing done, instead of waiting.
    int (*handle)(void *lane, const uint8_t *data, size_t size) noexcept nogil
    void *lane
    int (*try_handle)(void *lane, const uint8_t *data, size_t size) noexcept nogil


cdef enum:
    _HANDLED = 0
    _TO_PYTHON = 1
    _HANDLED_SETTLE = 2
    _BUSY = 3
    _NOT_YET = 4  # taken, not handled yet


cdef struct _Shared:
    # What the middleware's threads and the reader's share.
    pthread_mutex_t lock  # guards the next two
    pthread_cond_t cond
    size_t arrived  # messages told since the reader's thread last looked
    bint woken  # `wake` was called
    # Held by whoever takes and handles messages: the reader's thread, or a middleware
    # thread in `_take_here`. Guards the rest.
    pthread_mutex_t take_lock
    bint python_has  # Python holds messages taken: none is taken in a callback meanwhile
    bint handed  # a callback took a message its handler left to Python: `inline_message`
    const rcl_subscription_t *handed_subscription
    int handed_result  # the handler's: _TO_PYTHON, _BUSY, or _HANDLED_SETTLE (done)
    rcl_serialized_message_t inline_message  # the buffer callbacks take into


cdef struct _Tell:
    # One subscription's callback data.
    _Shared *shared
    const rcl_subscription_t *subscription
    _Handler *handler  # NULL: the reader's thread takes its messages


# Never traced, in the coverage build either (tools/native_coverage.py): a middleware thread
# has no tracer, and tracing would take the interpreter's lock there.
@cython.linetrace(False)
@cython.profile(False)
cdef void _on_new_messages(const void *user_data, size_t count) noexcept nogil:
    # A middleware thread: no interpreter, no allocation but the take's, as short as can be.
    cdef _Tell *tell = <_Tell *>user_data
    cdef _Shared *shared = tell.shared
    if tell.handler != NULL and _take_here(tell):
        return
    pthread_mutex_lock(&shared.lock)
    shared.arrived += count
    pthread_cond_signal(&shared.cond)
    pthread_mutex_unlock(&shared.lock)


@cython.linetrace(False)  # a middleware thread's, as above
@cython.profile(False)
cdef bint _take_here(_Tell *tell) noexcept nogil:
    """Take ``tell``'s messages and hand each to its native handler, in the middleware's
    thread; True when none is left. False leaves them to the reader's thread: it is taking
    now, or Python holds messages taken before, or the handler left one to Python (handed
    over), or rcl refused (the reader's thread meets the refusal too, and says so)."""
    cdef _Shared *shared = tell.shared
    cdef rmw_message_info_t info
    cdef rcl_ret_t ret = RCL_RET_OK
    cdef int handled
    if pthread_mutex_trylock(&shared.take_lock) != 0:
        return False
    if not shared.python_has:
        while True:
            ret = rcl_take_serialized_message(tell.subscription, &shared.inline_message,
                                              &info, NULL)
            if ret != RCL_RET_OK:
                break
            # Never waits: this thread holds the middleware's locks (the reader's among
            # them), which a Python thread holding the interpreter may be waiting for.
            handled = tell.handler.try_handle(tell.handler.lane,
                                              shared.inline_message.buffer,
                                              shared.inline_message.buffer_length)
            if handled != _HANDLED:
                shared.python_has = True
                shared.handed = True
                shared.handed_subscription = tell.subscription
                shared.handed_result = handled
                break
        if ret != RCL_RET_OK and ret != RCL_RET_SUBSCRIPTION_TAKE_FAILED:
            rcutils_reset_error()  # this thread's; the reader's thread reports its own
    pthread_mutex_unlock(&shared.take_lock)
    return ret == RCL_RET_SUBSCRIPTION_TAKE_FAILED


cdef enum:  # what `_take_first` found
    _TOOK = 0  # a message, in `_message`; take_lock held
    _HANDED_OVER = 1  # `handed`; take_lock held
    _NOTHING = 2  # the time passed, or `wake` was called


cdef class RawReader:
    """Takes serialized messages of ``subscriptions`` (rclpy's `_rclpy.Subscription`
    handles, which the caller keeps alive and destroys after `close` or after
    `set_subscriptions` let them go) in turn, waiting for them without the interpreter's
    lock. One thread calls `take` (or `take_batch`) and `set_subscriptions`; any thread
    may call `wake`."""

    cdef rcl_serialized_message_t _message
    cdef rcl_allocator_t _allocator
    cdef const rcl_subscription_t **_subscriptions
    cdef _Handler **_handlers  # per subscription, NULL for none
    cdef _Tell *_tells  # per subscription, what its callback is given
    cdef object _handler_owners  # what keeps the handlers alive
    cdef size_t _count
    cdef size_t _next
    cdef _Shared *_shared
    cdef bint _open

    def __cinit__(self, subscriptions):
        cdef pthread_condattr_t attr
        self._open = False
        self._count = 0
        self._subscriptions = NULL
        self._handlers = NULL
        self._tells = NULL
        self._handler_owners = ()
        self._shared = <_Shared *>calloc(1, sizeof(_Shared))
        if self._shared == NULL:
            raise MemoryError()
        pthread_mutex_init(&self._shared.lock, NULL)
        pthread_mutex_init(&self._shared.take_lock, NULL)
        pthread_condattr_init(&attr)
        pthread_condattr_setclock(&attr, CLOCK_MONOTONIC)
        pthread_cond_init(&self._shared.cond, &attr)
        pthread_condattr_destroy(&attr)
        self._allocator = rcl_get_default_allocator()
        self._message = rmw_get_zero_initialized_serialized_message()
        self._shared.inline_message = rmw_get_zero_initialized_serialized_message()
        if (rmw_serialized_message_init(&self._message, 0, &self._allocator) != RCL_RET_OK
                or rmw_serialized_message_init(&self._shared.inline_message, 0,
                                               &self._allocator) != RCL_RET_OK):
            rcutils_reset_error()
            raise ReaderError("rmw_serialized_message_init failed")
        self._open = True
        self.set_subscriptions(subscriptions)

    def take(self, double timeout_s):
        """``(index, view)``: the next message of subscription ``index``, as a read-only
        view valid until the next call; None when ``timeout_s`` passed or `wake` was
        called with nothing to take. Subscriptions take turns, so a busy one cannot
        starve the others. For a reader without native handlers (`take_batch` runs them)."""
        cdef size_t index = 0
        cdef int found = self._take_first(timeout_s, &index)
        if found == _NOTHING:
            return None
        pthread_mutex_unlock(&self._shared.take_lock)
        if found == _HANDED_OVER:  # only a handler hands over, and `take` sets none
            raise ReaderError("a native handler's message came to `take`: use take_batch")
        return index, PyMemoryView_FromMemory(<char *>self._message.buffer,
                                              <Py_ssize_t>self._message.buffer_length,
                                              PyBUF_READ)

    def take_batch(self, double timeout_s, size_t max_count, size_t max_bytes):
        """``(index, messages)``: `take`'s message and those of the same subscription
        waiting after it (`take_more`), each copied to bytes, in order; None as `take`.
        A subscription's native handler takes its messages first (in the middleware's
        callback, or in this thread), and only what it leaves comes back: the message it
        did not take and the rest of its batch, or an empty list when it asks Python to
        settle after one it took. Python is done with a batch when it asks for the next."""
        cdef size_t index = 0
        cdef int handled
        cdef int found
        cdef rcl_serialized_message_t *message
        cdef _Handler *handler
        cdef int64_t deadline = _now_ns() + <int64_t>(timeout_s * 1e9)
        cdef _Shared *shared = self._shared
        with nogil:
            pthread_mutex_lock(&shared.take_lock)
            shared.python_has = shared.handed  # the batch before is done; a handed one waits
            pthread_mutex_unlock(&shared.take_lock)
        while True:
            found = self._take_first(max(0.0, (deadline - _now_ns()) / 1e9), &index)
            if found == _NOTHING:
                return None
            # take_lock is held until the message is handled or Python has it.
            if found == _HANDED_OVER:
                shared.handed = False
                message = &shared.inline_message  # untouched while Python has the batch
                handled = shared.handed_result
                if not self._index_of(shared.handed_subscription, &index):
                    shared.python_has = False  # its subscription was let go meanwhile
                    pthread_mutex_unlock(&shared.take_lock)
                    continue
            else:
                message = &self._message
                handled = _NOT_YET
            if handled == _NOT_YET or handled == _BUSY:
                handler = self._handlers[index] if self._handlers != NULL else NULL
                if handler == NULL:
                    handled = _TO_PYTHON
                else:
                    with nogil:
                        handled = handler.handle(handler.lane, message.buffer,
                                                 message.buffer_length)
            shared.python_has = handled != _HANDLED
            pthread_mutex_unlock(&shared.take_lock)
            if handled == _HANDLED_SETTLE:
                return index, []
            if handled != _HANDLED:
                break
            if shared.woken or _now_ns() >= deadline:  # the caller has work too
                return None
        data = PyBytes_FromStringAndSize(<char *>message.buffer,
                                         <Py_ssize_t>message.buffer_length)
        if max_count <= 1 or <size_t>len(data) >= max_bytes:
            return index, [data]
        more = self.take_more(index, max_count - 1, max_bytes - len(data))
        more.insert(0, data)
        return index, more

    cdef bint _index_of(self, const rcl_subscription_t *subscription, size_t *index) noexcept:
        cdef size_t i
        for i in range(self._count):
            if self._subscriptions[i] == subscription:
                index[0] = i
                return True
        return False

    cdef int _take_first(self, double timeout_s, size_t *taken) except -1:
        """Take the next message into `_message` (_TOOK, its subscription in ``taken``), or
        find one a callback handed over (_HANDED_OVER), both with `take_lock` held;
        _NOTHING when ``timeout_s`` passed or `wake` was called. Waits up to ``timeout_s``."""
        cdef rcl_ret_t ret = RCL_RET_SUBSCRIPTION_TAKE_FAILED
        cdef rmw_message_info_t info
        cdef size_t tried, index = 0
        cdef int64_t deadline = _now_ns() + <int64_t>(timeout_s * 1e9)
        cdef timespec until
        cdef bint woken = False, handed = False
        cdef size_t arrived = 0
        cdef _Shared *shared = self._shared
        if not self._open:
            raise ReaderError("the reader is closed")
        until.tv_sec = deadline // 1000000000
        until.tv_nsec = deadline % 1000000000
        with nogil:
            while True:
                pthread_mutex_lock(&shared.take_lock)
                handed = shared.handed
                if handed:
                    break
                tried = 0
                while tried < self._count:
                    index = (self._next + tried) % self._count
                    ret = rcl_take_serialized_message(self._subscriptions[index],
                                                      &self._message, &info, NULL)
                    if ret == RCL_RET_OK:
                        break
                    if ret != RCL_RET_SUBSCRIPTION_TAKE_FAILED:
                        break
                    tried += 1
                if ret == RCL_RET_OK:
                    break
                pthread_mutex_unlock(&shared.take_lock)
                if ret != RCL_RET_SUBSCRIPTION_TAKE_FAILED:
                    break
                # Nothing to take: wait until the middleware says more came. Told before
                # the lock was taken, it is not waited for.
                pthread_mutex_lock(&shared.lock)
                while shared.arrived == 0 and not shared.woken and _now_ns() < deadline:
                    pthread_cond_timedwait(&shared.cond, &shared.lock, &until)
                woken = shared.woken
                shared.woken = False
                arrived = shared.arrived
                shared.arrived = 0
                pthread_mutex_unlock(&shared.lock)
                if woken or arrived == 0:
                    break
        if handed:
            return _HANDED_OVER
        if ret == RCL_RET_OK:
            self._next = (index + 1) % self._count
            taken[0] = index
            return _TOOK
        if ret == RCL_RET_SUBSCRIPTION_TAKE_FAILED:
            return _NOTHING
        rcutils_reset_error()
        raise ReaderError(f"rcl returned {ret} while taking a message")

    @property
    def handed_over(self):
        """A callback took a message its handler could not write then; `take_batch` has
        it next."""
        return bool(self._shared.handed)

    def wake(self):
        """End a `take` that waits (any thread)."""
        if self._shared != NULL:
            with nogil:
                pthread_mutex_lock(&self._shared.lock)
                self._shared.woken = True
                pthread_cond_signal(&self._shared.cond)
                pthread_mutex_unlock(&self._shared.lock)

    def set_subscriptions(self, subscriptions, handlers=None):
        """Take ``subscriptions`` (any number, none too) from now on, in place of those
        before: the middleware no longer calls this reader for those let go, which the
        caller may destroy then. ``handlers``: for each, a native lane's handler capsule
        (`PoseLane.handler`) or None. Called by the thread that calls `take`, between two."""
        if not self._open:
            raise ReaderError("the reader is closed")
        cdef size_t count = len(subscriptions)
        if handlers is not None and len(handlers) != count:
            raise ValueError(f"handlers: expected one per subscription ({count}), got "
                             f"{len(handlers)}")
        cdef _Handler **natives = _handler_pointers(handlers, count)
        cdef const rcl_subscription_t **pointers = NULL
        cdef _Tell *tells = NULL
        try:
            pointers = _pointers(subscriptions)
            if count:
                tells = <_Tell *>calloc(count, sizeof(_Tell))
                if tells == NULL:
                    raise MemoryError()
        except BaseException:
            free(pointers)
            free(natives)
            raise
        cdef size_t i, j
        cdef bint kept
        for j in range(count):
            tells[j].shared = self._shared
            tells[j].subscription = pointers[j]
            tells[j].handler = natives[j] if natives != NULL else NULL
        for i in range(self._count):  # those let go: the middleware forgets this reader
            kept = False
            for j in range(count):
                kept = kept or pointers[j] == self._subscriptions[i]
            if not kept:
                _set_callback(self._subscriptions[i], NULL, NULL)
                self._forget_handed(self._subscriptions[i])
        # Each callback's data is replaced: the middleware holds its listener's lock
        # while it calls one, so none runs with the old data after this.
        for j in range(count):
            if _set_callback(pointers[j], _on_new_messages, &tells[j]) != RCL_RET_OK:
                rcutils_reset_error()
                for i in range(j):
                    _set_callback(pointers[i], NULL, NULL)
                    self._forget_handed(pointers[i])
                free(pointers)
                free(natives)
                free(tells)
                raise ReaderError("the middleware does not tell new messages "
                                  "(rcl_subscription_set_on_new_message_callback)")
        free(self._subscriptions)
        free(self._handlers)
        free(self._tells)
        self._subscriptions = pointers
        self._handlers = natives
        self._tells = tells
        self._handler_owners = tuple(handlers) if handlers is not None else ()
        self._count = count
        self._next = 0

    cdef void _forget_handed(self, const rcl_subscription_t *subscription) noexcept:
        """A message handed over from ``subscription``, let go, is dropped with it."""
        with nogil:
            pthread_mutex_lock(&self._shared.take_lock)
            if self._shared.handed and self._shared.handed_subscription == subscription:
                self._shared.handed = False
                self._shared.python_has = False
            pthread_mutex_unlock(&self._shared.take_lock)

    def take_more(self, size_t index, size_t max_count, size_t max_bytes):
        """The messages of subscription ``index`` already waiting, in order, each copied
        to bytes, without waiting: at most ``max_count``, and none after the one that
        brings the total to ``max_bytes``. The view `take` gave is invalid afterwards.
        After `take_batch`'s first message, so no callback takes meanwhile."""
        cdef rcl_ret_t ret = RCL_RET_OK
        cdef rmw_message_info_t info
        cdef size_t total = 0
        if not self._open:
            raise ReaderError("the reader is closed")
        if index >= self._count:
            raise IndexError(f"index: expected below {self._count}, got {index}")
        taken = []
        while <size_t>len(taken) < max_count and total < max_bytes:
            with nogil:
                ret = rcl_take_serialized_message(self._subscriptions[index], &self._message,
                                                  &info, NULL)
            if ret != RCL_RET_OK:
                break
            total += self._message.buffer_length
            taken.append(PyBytes_FromStringAndSize(<char *>self._message.buffer,
                                                   <Py_ssize_t>self._message.buffer_length))
        if ret != RCL_RET_OK and ret != RCL_RET_SUBSCRIPTION_TAKE_FAILED:
            rcutils_reset_error()
            raise ReaderError(f"rcl returned {ret} while taking a message")
        return taken

    def close(self):
        """Let go of the subscriptions and free the buffers (the subscriptions are the
        caller's, to destroy after this)."""
        cdef size_t i
        if self._open:
            self._open = False
            for i in range(self._count):  # after these, no callback runs
                _set_callback(self._subscriptions[i], NULL, NULL)
            if (rmw_serialized_message_fini(&self._message) != RCL_RET_OK
                    or rmw_serialized_message_fini(&self._shared.inline_message) != RCL_RET_OK):
                rcutils_reset_error()  # nothing more to do about it

    def __dealloc__(self):
        self.close()
        free(self._subscriptions)
        self._subscriptions = NULL
        free(self._handlers)
        self._handlers = NULL
        free(self._tells)
        self._tells = NULL
        if self._shared != NULL:
            pthread_cond_destroy(&self._shared.cond)
            pthread_mutex_destroy(&self._shared.lock)
            pthread_mutex_destroy(&self._shared.take_lock)
            free(self._shared)
            self._shared = NULL


@cython.linetrace(False)  # a middleware thread's, as above
@cython.profile(False)
cdef void _ignore_new_messages(const void *user_data, size_t count) noexcept nogil:
    pass


def check_tells_new_messages(subscription):
    """Raise ReaderError unless the middleware tells ``subscription``'s new messages (an
    rclpy `_rclpy.Subscription` handle); leaves no callback set."""
    cdef const rcl_subscription_t *pointer = <const rcl_subscription_t *><size_t>(
        subscription.pointer)
    if _set_callback(pointer, _ignore_new_messages, NULL) != RCL_RET_OK:
        rcutils_reset_error()
        raise ReaderError("the middleware does not tell new messages "
                          "(rcl_subscription_set_on_new_message_callback)")
    _set_callback(pointer, NULL, NULL)


cdef rcl_ret_t _set_callback(const rcl_subscription_t *subscription,
                             rcl_event_callback_t callback, const void *user_data) noexcept:
    cdef rcl_ret_t ret
    with nogil:  # the middleware takes its listener's lock, which its threads hold a while
        ret = rcl_subscription_set_on_new_message_callback(subscription, callback, user_data)
    return ret


cdef const rcl_subscription_t **_pointers(subscriptions) except? NULL:
    """The rcl subscriptions of rclpy's handles, in a new array (NULL for none)."""
    cdef size_t count = len(subscriptions)
    if count == 0:
        return NULL
    cdef const rcl_subscription_t **pointers = <const rcl_subscription_t **>calloc(
        count, sizeof(rcl_subscription_t *))
    if pointers == NULL:
        raise MemoryError()
    try:
        for i, subscription in enumerate(subscriptions):
            pointers[i] = <const rcl_subscription_t *><size_t>subscription.pointer
    except BaseException:
        free(pointers)
        raise
    return pointers


cdef _Handler **_handler_pointers(handlers, size_t count) except? NULL:
    """The handlers of the capsules in ``handlers`` (None: none), in a new array; NULL when
    there is none at all."""
    if handlers is None or not any(h is not None for h in handlers):
        return NULL
    cdef _Handler **pointers = <_Handler **>calloc(count, sizeof(_Handler *))
    if pointers == NULL:
        raise MemoryError()
    try:
        for i, handler in enumerate(handlers):
            if handler is not None:
                pointers[i] = <_Handler *>PyCapsule_GetPointer(handler, HANDLER_CAPSULE)
    except BaseException:
        free(pointers)
        raise
    return pointers


# bridge/core/_native_stream.pyx's capsule name.
cdef const char *HANDLER_CAPSULE = "bridge.core.native_stream.Handler3"


cdef inline int64_t _now_ns() noexcept nogil:
    cdef timespec now
    clock_gettime(CLOCK_MONOTONIC, &now)
    return <int64_t>now.tv_sec * 1000000000 + now.tv_nsec
