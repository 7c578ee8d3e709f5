/*
 * The processor-in-the-loop target: the controller (fpc.h) driven by a host master over two
 * host files (named pipes) through semihosting, one request and one reply at a time.
 *
 * A request is a little-endian u32 body length, then the body: an operation byte and its
 * arguments.  Every reply is: i32 status (FpStatus), u32 ticks (the board timer over the
 * operation's controller call), u32 format calls and u32 heap bytes of the C library so far,
 * u32 stack bytes so far (since the start, after it: the samples' depth), u32 length + values, u32 length + the messages said (text).
 *
 *   'h'                                   hello: values = the model's GUID (text)
 *   'R' u32 n, u32 vr[n], f64 v[n]        fpc_set_reals_vr
 *   'I' u32 n, u32 vr[n], i32 v[n]        fpc_set_ints_vr (Integer and Boolean)
 *   'r' u32 n, u32 vr[n]                  fpc_get_reals_vr: values f64[n]
 *   'i' u32 n, u32 vr[n]                  fpc_get_ints_vr: values i32[n]
 *   's' f64 t0                            fpc_start (inputs as set)
 *   'x' f64 t, u32 n, u32 vr[n], f64 v[n], u32 nr, u32 vr[nr], u32 ni, u32 vr[ni]
 *                                         one sample: set the inputs, fpc_step at t, then
 *                                         values f64[nr], i32[ni]
 *   'm' u8 f, u32 n, f64 x[n], f64 y[n]  the board's libm: values f64[n] of function f (0 sin,
 *                                         1 cos, 2 tan, 3 asin, 4 acos, 5 atan2(x, y),
 *                                         6 hypot(x, y)), the functions the controller calls
 *                                         that are not exact by definition
 *   'l' u8 on                             record the controller's calls of those functions
 *                                         (the tracing image only)
 *   'L'                                   the calls recorded since the last 'L': u32 dropped,
 *                                         then per call f64 function, x, y, result
 *   'c' u32 n                             calibration: a loop of exactly 2 n + 2 instructions
 *                                         between the timer reads (ticks: its count)
 *   'd'                                   fpc_defaults
 *   'q'                                   stop (QEMU exits 0)
 *
 * The two pipes are "pil.in" (requests) and "pil.out" (replies) in the folder QEMU runs in
 * (orchestrator/pil/target.py makes them).  A host writes larger requests in parts.
 */
#include <math.h>
#include <stdint.h>
#include <string.h>

#include "board.h"
#include "fpc.h"
#include "semihost.h"

#define MAX_VALUES 512            /* elements in one request (a host sends more in parts) */
#define MAX_REQUEST (16 + 16 * MAX_VALUES)
#define MAX_TEXT 4096             /* messages carried by one reply */

typedef struct {
    FpcController ctrl;
    int in, out;
    unsigned char request[MAX_REQUEST] __attribute__((aligned(8)));
    unsigned char values[8 * MAX_VALUES + 8 + sizeof(BoardLibmCall) * BOARD_LIBM_LOG]
        __attribute__((aligned(8)));
    uint32_t n_values; /* bytes */
    char text[MAX_TEXT];
    uint32_t n_text;
    uint32_t refs[MAX_VALUES];
    double reals[MAX_VALUES];
    int32_t ints[MAX_VALUES];
} Pil;

static void keep_message(void *env, FpStatus status, const char *message) {
    Pil *p = (Pil *)env;
    static const char *const tags[] = {"", "warning: ", "discard: ", "error: "};
    const char *tag = (unsigned)status < 4u ? tags[status] : "";
    size_t room = MAX_TEXT - p->n_text, a = strlen(tag), b = strlen(message);
    if (room < a + b + 1) return; /* the reply's text is full: the rest is dropped */
    memcpy(p->text + p->n_text, tag, a);
    memcpy(p->text + p->n_text + a, message, b);
    p->text[p->n_text + a + b] = '\n';
    p->n_text += (uint32_t)(a + b + 1);
}

/* A cursor over the request body: every read checks the bounds. */
typedef struct {
    const unsigned char *at, *end;
    int bad;
} Cursor;

static void take(Cursor *c, void *dst, size_t n) {
    if (c->bad || (size_t)(c->end - c->at) < n) {
        c->bad = 1;
        memset(dst, 0, n);
        return;
    }
    memcpy(dst, c->at, n);
    c->at += n;
}

static uint32_t take_u32(Cursor *c) {
    uint32_t v;
    take(c, &v, sizeof v);
    return v;
}

static double take_f64(Cursor *c) {
    double v;
    take(c, &v, sizeof v);
    return v;
}

/* n value references; 0 when n exceeds the cap (the cursor marked bad). */
static uint32_t take_refs(Cursor *c, uint32_t *refs) {
    uint32_t n = take_u32(c);
    if (n > MAX_VALUES) {
        c->bad = 1;
        return 0;
    }
    take(c, refs, (size_t)n * sizeof(uint32_t));
    return n;
}

static void put(Pil *p, const void *src, size_t n) {
    if (p->n_values + n > sizeof p->values) return; /* (bounded by MAX_VALUES per request) */
    memcpy(p->values + p->n_values, src, n);
    p->n_values += (uint32_t)n;
}

static int reply(Pil *p, int32_t status, uint32_t ticks) {
    uint32_t head[7];
    head[0] = (uint32_t)status;
    head[1] = ticks;
    head[2] = board_format_calls();
    head[3] = (uint32_t)board_heap_used();
    head[4] = (uint32_t)board_stack_used();
    head[5] = p->n_values;
    if (semihost_write_all(p->out, head, 6 * sizeof(uint32_t)) != 0) return -1;
    if (p->n_values > 0 && semihost_write_all(p->out, p->values, p->n_values) != 0) return -1;
    head[6] = p->n_text;
    if (semihost_write_all(p->out, &head[6], sizeof(uint32_t)) != 0) return -1;
    if (p->n_text > 0 && semihost_write_all(p->out, p->text, p->n_text) != 0) return -1;
    p->n_values = 0;
    p->n_text = 0;
    return 0;
}

/* n value references, then n reals, into p->refs and p->reals ('R' and 'x'). */
static uint32_t take_reals(Pil *p, Cursor *c) {
    uint32_t n = take_refs(c, p->refs), i;
    for (i = 0; i < n; i++) p->reals[i] = take_f64(c);
    return n;
}

/* One sample ('x'). */
static int32_t sample(Pil *p, Cursor *c, uint32_t *ticks) {
    double t = take_f64(c);
    uint32_t n = take_reals(p, c), nr, ni;
    FpStatus s;
    if (c->bad) return FP_ERROR;
    s = fpc_set_reals_vr(&p->ctrl, p->refs, n, p->reals);
    if (s != FP_OK) return s;
    board_timer_restart();
    s = fpc_step(&p->ctrl, t, NULL, NULL);
    *ticks = board_timer_ticks();
    if (s == FP_ERROR) return s;
    nr = take_refs(c, p->refs);
    if (c->bad || fpc_get_reals_vr(&p->ctrl, p->refs, nr, p->reals) != FP_OK) return FP_ERROR;
    put(p, p->reals, (size_t)nr * sizeof(double));
    ni = take_refs(c, p->refs);
    if (c->bad || fpc_get_ints_vr(&p->ctrl, p->refs, ni, p->ints) != FP_OK) return FP_ERROR;
    put(p, p->ints, (size_t)ni * sizeof(int32_t));
    return s;
}

/* 'c': n turns of a two-instruction loop (subs, bne) after a mov, with the timer restarted
 * before and read after; the host checks the ticks against 2 n + 2 instructions plus the
 * reads' own (the same for every n), the measuring chain's calibration. */
static uint32_t calibrate(uint32_t n) {
    uint32_t ticks;
    board_timer_restart();
    __asm__ volatile("movs r0, %0\n"
                     "1: subs r0, r0, #1\n"
                     "bne 1b\n"
                     :
                     : "r"(n)
                     : "r0", "cc");
    ticks = board_timer_ticks();
    return ticks;
}

/* The board's libm on the host's arguments ('m'). */
static int32_t libm(Pil *p, Cursor *c) {
    unsigned char f;
    uint32_t n, i;
    take(c, &f, 1);
    n = take_u32(c);
    if (n > MAX_VALUES / 2 || f > 6) c->bad = 1;
    if (c->bad) return FP_ERROR;
    for (i = 0; i < 2 * n; i++) p->reals[i] = take_f64(c);
    if (c->bad) return FP_ERROR;
    for (i = 0; i < n; i++) {
        double x = p->reals[i], y = p->reals[n + i], r;
        switch (f) {
        case 0: r = sin(x); break;
        case 1: r = cos(x); break;
        case 2: r = tan(x); break;
        case 3: r = asin(x); break;
        case 4: r = acos(x); break;
        case 5: r = atan2(x, y); break;
        default: r = hypot(x, y); break;
        }
        put(p, &r, sizeof r);
    }
    return FP_OK;
}

static int32_t serve(Pil *p, unsigned char op, Cursor *c, uint32_t *ticks) {
    uint32_t n, i;
    FpStatus s;
    char guid[40];
    switch (op) {
    case 'h':
        fp_model_guid(controller_model_info(), guid);
        put(p, guid, strlen(guid));
        return FP_OK;
    case 'd': return fpc_defaults(&p->ctrl, keep_message, p);
    case 'R':
        n = take_reals(p, c);
        return c->bad ? FP_ERROR : fpc_set_reals_vr(&p->ctrl, p->refs, n, p->reals);
    case 'I':
        n = take_refs(c, p->refs);
        for (i = 0; i < n; i++) p->ints[i] = (int32_t)take_u32(c);
        return c->bad ? FP_ERROR : fpc_set_ints_vr(&p->ctrl, p->refs, n, p->ints);
    case 'r':
        n = take_refs(c, p->refs);
        if (c->bad) return FP_ERROR;
        s = fpc_get_reals_vr(&p->ctrl, p->refs, n, p->reals);
        if (s == FP_OK) put(p, p->reals, (size_t)n * sizeof(double));
        return s;
    case 'i':
        n = take_refs(c, p->refs);
        if (c->bad) return FP_ERROR;
        s = fpc_get_ints_vr(&p->ctrl, p->refs, n, p->ints);
        if (s == FP_OK) put(p, p->ints, (size_t)n * sizeof(int32_t));
        return s;
    case 's': {
        double t0 = take_f64(c);
        if (c->bad) return FP_ERROR;
        board_timer_restart();
        s = fpc_start(&p->ctrl, t0, NULL);
        *ticks = board_timer_ticks();
        return s;
    }
    case 'x': return sample(p, c, ticks);
    case 'm': return libm(p, c);
    case 'c': {
        uint32_t n = take_u32(c);
        if (c->bad || n == 0) return FP_ERROR;
        *ticks = calibrate(n);
        return FP_OK;
    }
    case 'l': {
        unsigned char on;
        take(c, &on, 1);
        if (c->bad) return FP_ERROR;
        if (board_libm_record(on != 0)) return FP_OK;
        keep_message(p, FP_ERROR, "this image does not record libm calls (fpc_pil_trace.elf does)");
        return FP_ERROR;
    }
    case 'L': {
        uint32_t k, dropped;
        const BoardLibmCall *calls = board_libm_take(&k, &dropped);
        put(p, &dropped, sizeof dropped);
        put(p, calls, (size_t)k * sizeof *calls);
        return FP_OK;
    }
    default: return FP_ERROR;
    }
}

int pil_main(void) {
    static Pil pil; /* the image's one session, in .bss */
    Pil *p = &pil;
    board_paint_stack();
    fpc_defaults(&p->ctrl, keep_message, p);
    p->in = semihost_open("pil.in", 0);
    p->out = p->in < 0 ? -1 : semihost_open("pil.out", 1);
    if (p->in < 0 || p->out < 0) {
        semihost_say("pil: cannot open pil.in / pil.out in QEMU's working folder\n");
        return 2;
    }
    for (;;) {
        uint32_t length, ticks = 0;
        Cursor c;
        unsigned char op;
        int32_t status;
        if (semihost_read_all(p->in, &length, sizeof length) != 0) return 0; /* host gone */
        if (length == 0 || length > MAX_REQUEST ||
            semihost_read_all(p->in, p->request, length) != 0) {
            semihost_say("pil: malformed request length\n");
            return 4;
        }
        op = p->request[0];
        if (op == 'q') return 0;
        c.at = p->request + 1;
        c.end = p->request + length;
        c.bad = 0;
        status = serve(p, op, &c, &ticks);
        if (c.bad) keep_message(p, FP_ERROR, "pil: a request's arguments were cut short");
        if (reply(p, status, ticks) != 0) return 5;
        /* from the start on, the stack depth measured is the samples' (initialization,
         * which derives the force sets, goes deeper: its reply said how deep) */
        if (op == 's') board_paint_stack();
    }
}
