/* QEMU TCG plugin (host side of the processor-in-the-loop target): counts the guest instructions
 * executed between marker functions and writes one line `NAME COUNT` per measured interval.
 *
 *   qemu-system-arm ... -plugin build/pil/insn_count.so,out=FILE,law=BEGIN:END,cycle=BEGIN:END
 *
 * BEGIN and END are the (hex) entry addresses of pil_law_begin/pil_law_end etc. (pil.h). COUNT is
 * the instructions from the return of BEGIN's call to the call of END, both excluded: with the
 * markers called back to back it is 0. Debian's QEMU 7.2 is built with plugin support but ships
 * no plugin and no qemu-plugin.h: the few API v1 calls used are declared here as that header
 * declares them (the ABI is C symbols of the QEMU binary). */
#include <inttypes.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

typedef uint64_t qemu_plugin_id_t;
struct qemu_plugin_tb;
struct qemu_plugin_insn;
enum { QEMU_PLUGIN_CB_NO_REGS = 0 };
enum { QEMU_PLUGIN_INLINE_ADD_U64 = 0 };
typedef void (*udata_cb_t)(unsigned int vcpu_index, void *userdata);
typedef void (*tb_trans_cb_t)(qemu_plugin_id_t id, struct qemu_plugin_tb *tb);
typedef void (*atexit_cb_t)(qemu_plugin_id_t id, void *userdata);

void qemu_plugin_register_vcpu_tb_trans_cb(qemu_plugin_id_t id, tb_trans_cb_t cb);
size_t qemu_plugin_tb_n_insns(const struct qemu_plugin_tb *tb);
struct qemu_plugin_insn *qemu_plugin_tb_get_insn(const struct qemu_plugin_tb *tb, size_t idx);
uint64_t qemu_plugin_insn_vaddr(const struct qemu_plugin_insn *insn);
void qemu_plugin_register_vcpu_insn_exec_cb(struct qemu_plugin_insn *insn, udata_cb_t cb, int flags, void *udata);
void qemu_plugin_register_vcpu_insn_exec_inline(struct qemu_plugin_insn *insn, int op, void *ptr, uint64_t imm);
void qemu_plugin_register_atexit_cb(qemu_plugin_id_t id, atexit_cb_t cb, void *userdata);

__attribute__((visibility("default"))) int qemu_plugin_version = 1;

#define MAX_MARKS 4

typedef struct {
    char name[16];
    uint64_t begin, end;
    uint64_t start; /* the counter at BEGIN's first instruction */
    int open;
} mark_t;

static mark_t marks[MAX_MARKS];
static int n_marks;
static uint64_t executed; /* every guest instruction, counted inline before it executes */
static FILE *out;

/* The counter is incremented after the callbacks of the same instruction: at BEGIN it counts
 * what came before BEGIN's first instruction, at END likewise; minus BEGIN's `bx lr` and the
 * `bl END`, that leaves the instructions between the two calls. */
static void at_begin(unsigned int vcpu, void *udata)
{
    mark_t *m = udata;
    (void)vcpu;
    m->start = executed;
    m->open = 1;
}

static void at_end(unsigned int vcpu, void *udata)
{
    mark_t *m = udata;
    (void)vcpu;
    if (m->open) {
        fprintf(out, "%s %" PRIu64 "\n", m->name, executed - m->start - 2u);
        m->open = 0;
    }
}

static void on_translate(qemu_plugin_id_t id, struct qemu_plugin_tb *tb)
{
    size_t i;
    int k;
    (void)id;
    for (i = 0; i < qemu_plugin_tb_n_insns(tb); ++i) {
        struct qemu_plugin_insn *insn = qemu_plugin_tb_get_insn(tb, i);
        const uint64_t pc = qemu_plugin_insn_vaddr(insn);
        for (k = 0; k < n_marks; ++k) {
            if (pc == marks[k].begin) {
                qemu_plugin_register_vcpu_insn_exec_cb(insn, at_begin, QEMU_PLUGIN_CB_NO_REGS, &marks[k]);
            } else if (pc == marks[k].end) {
                qemu_plugin_register_vcpu_insn_exec_cb(insn, at_end, QEMU_PLUGIN_CB_NO_REGS, &marks[k]);
            }
        }
        qemu_plugin_register_vcpu_insn_exec_inline(insn, QEMU_PLUGIN_INLINE_ADD_U64, &executed, 1);
    }
}

static void on_exit(qemu_plugin_id_t id, void *udata)
{
    (void)id;
    (void)udata;
    fprintf(out, "total %" PRIu64 "\n", executed);
    fclose(out);
}

__attribute__((visibility("default"))) int qemu_plugin_install(qemu_plugin_id_t id, const void *info, int argc,
                                                               char **argv)
{
    int i;
    (void)info;
    for (i = 0; i < argc; ++i) {
        char *eq = strchr(argv[i], '=');
        if (eq == NULL) {
            fprintf(stderr, "insn_count: argument %s is not KEY=VALUE\n", argv[i]);
            return -1;
        }
        *eq = '\0';
        if (strcmp(argv[i], "out") == 0) {
            out = fopen(eq + 1, "w");
        } else if (n_marks < MAX_MARKS) {
            mark_t *m = &marks[n_marks++];
            char *end;
            snprintf(m->name, sizeof m->name, "%s", argv[i]);
            m->begin = strtoull(eq + 1, &end, 16);
            m->end = (*end == ':') ? strtoull(end + 1, NULL, 16) : 0u;
        }
    }
    if (out == NULL) {
        fprintf(stderr, "insn_count: out=FILE missing or not writable\n");
        return -1;
    }
    qemu_plugin_register_vcpu_tb_trans_cb(id, on_translate);
    qemu_plugin_register_atexit_cb(id, on_exit, NULL);
    return 0;
}
