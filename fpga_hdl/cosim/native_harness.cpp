// The co-simulation harness (fpga_hdl.cosim.harness) driven from compiled code.
//
// Built by fpga_hdl.cosim.native with Verilator (--cc, no --timing) into a shared library
// that Python loads with ctypes. Each call runs one whole transaction inside the
// simulator: an SPI transfer, an I2C write/read, a host-port burst write or read, a GPS
// UART exchange, or N cycles of the PWM capture clock. So Python pays one call per
// transaction, never one per clock edge.
//
// Clocks. For this build the harness's `cosim_gated_clock` is NATIVE_CLOCK_VERILOG
// (fpga_hdl.cosim.native): a register that this file sets to 1 and that clears itself
// on its own rising edge, so one eval() is one whole clock cycle. The system clock
// follows the gated clock's rule: whole cycles while its `enable` (the harness's
// `sync_run`) is high, checked after every cycle; so do the SPI controller's clock, which
// only an SPI transfer enables (its cycles then run alone, and the system clock's settle
// cycles after them), the I2C clock (the I2C bus's controller and chips alone), which only
// an I2C transfer enables, and the UART clock (the GPS receiver's domain and the autopilot's
// UART), which only a UART exchange enables.
//
// By event. Where the harness's `pwm_quiet` says the next capture-clock edges move
// nothing but counters (no PWM output changes, no period starts, the capture's pipeline
// at rest, no timeout due), one edge stands for that many ticks (`pwm_skip`, the RTL's own
// counters add them), so a PWM period costs a few edges around each pulse edge instead of
// one per tick. nh_pwm_by_event turns it off: the tests compare both, tick for tick. The
// UART clock likewise (`uart_quiet`, `uart_skip`): between the bit edges and samples of
// both ends of the GPS line only bit timers move, so a byte costs a few dozen edges
// instead of ten bit times; nh_uart_by_event turns it off. The I2C clock likewise
// (`i2c_quiet`, `i2c_skip`): while both chips are settled (their synchronisers and filters
// hold the bus's levels, no SDA change waits out its hold time) only the controller's
// duration counter moves until its next SCL or SDA change, so a bit costs the edges
// around its bus events; nh_i2c_by_event turns it off.
//
// Costs: every call that clocks the design adds its wall time and cycles to a slot
// (nh_costs): one per SPI device, per I2C address, the host writes, the host reads, the
// UART exchanges and the capture clock. That is the per-frame budget `make bench` prints,
// measured where it is spent.
//
// Errors: every function returns 0 on success and -1 on failure, with the reason in
// nh_error(). Ports are copied as little-endian bytes, whatever their Verilated type.

#include <algorithm>
#include <chrono>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <string>

#include "Vharness.h"
#include "Vharness___024root.h"
#include "verilated.h"

// The root members of the clocks' registers and the gated ones' enables, given by
// fpga_hdl.cosim.native as -D flags (their names follow the harness's hierarchy).
#if !defined(SYNC_CLOCK) || !defined(SYNC_ENABLE) || !defined(SPI_CLOCK) ||      \
    !defined(SPI_ENABLE) || !defined(I2C_CLOCK) || !defined(I2C_ENABLE) ||          \
    !defined(PWM_CLOCK) || !defined(UART_CLOCK) || !defined(UART_ENABLE)
#error "build through fpga_hdl.cosim.native: the clock and register -D flags are missing"
#endif

static_assert(__BYTE_ORDER__ == __ORDER_LITTLE_ENDIAN__, "ports are copied as little-endian");

namespace {

// More cycles than any transaction takes (an I2C transfer at 100 kHz is ~20 k system
// cycles, PX4's slowest GPS exchange at 9600 baud ~45 k UART cycles): a peripheral that
// never acknowledges is reported, not waited for forever.
constexpr uint64_t CYCLE_LIMIT = 10'000'000;

// The cost slots (see the top of this file; fpga_hdl.cosim.native names them).
constexpr size_t SPI_SLOTS = 8;  // by SPI device index
constexpr size_t I2C_SLOT = SPI_SLOTS;  // + the 7-bit address
constexpr size_t HOST_WRITE_SLOT = I2C_SLOT + 128;
constexpr size_t HOST_READ_SLOT = HOST_WRITE_SLOT + 1;
constexpr size_t UART_SLOT = HOST_READ_SLOT + 1;
constexpr size_t PWM_SLOT = UART_SLOT + 1;
constexpr size_t COST_SLOTS = PWM_SLOT + 1;

// What one kind of call has cost so far: calls, clock cycles, wall time.
struct Cost {
    uint64_t calls = 0;
    uint64_t cycles = 0;
    uint64_t ns = 0;
};

uint64_t now_ns() {
    return static_cast<uint64_t>(std::chrono::duration_cast<std::chrono::nanoseconds>(
        std::chrono::steady_clock::now().time_since_epoch()).count());
}

// Adds the wall time and the cycles of `counter` between construction and destruction.
class Charge {
  public:
    Charge(Cost& cost, const uint64_t& counter)
        : cost_{cost}, counter_{counter}, cycles_{counter}, started_{now_ns()} {}
    ~Charge() {
        cost_.calls += 1;
        cost_.cycles += counter_ - cycles_;
        cost_.ns += now_ns() - started_;
    }
    Charge(const Charge&) = delete;
    Charge& operator=(const Charge&) = delete;

  private:
    Cost& cost_;
    const uint64_t& counter_;
    uint64_t cycles_;
    uint64_t started_;
};

}  // namespace

// Verilator's own evaluation of the design (Vharness.cpp). `Vharness::eval()` wraps it
// with per-call bookkeeping for features this harness has none of (objects queued for
// deletion, messages from other threads): a mutex and a thread-local lookup on every
// clock cycle, a ninth of a capture cycle (106 → 94 ns measured) and 6-8 % of a system
// cycle. So each cycle calls it directly; the first `eval()` of each instance (its
// initial blocks) still goes through the model. (An internal name: a Verilator that
// renames it fails to load the library with "undefined symbol", it cannot run wrong.)
void Vharness___024root___eval(Vharness___024root* vlSelf);
// Its two scheduling phases after the input-combinational one: triggers, then the
// non-blocking assignments and the logic they feed, repeated until nothing triggers.
bool Vharness___024root___eval_phase__act(Vharness___024root* vlSelf);
bool Vharness___024root___eval_phase__nba(Vharness___024root* vlSelf);

namespace {

// One evaluation of `model`: inputs written by the caller settle, or a clock edge.
void evaluate(Vharness& model) { Vharness___024root___eval(model.rootp); }

// A clock edge with every input as the last `evaluate` saw it. `eval()` begins with the
// input-combinational phase, which recomputes the logic of the ports (logic that reads
// registers too is recomputed after the edge as well): with the ports unchanged it moves
// nothing, so a cycle skips it: 16 % of the compiled frame's instructions and 15 % of its
// time, measured (the system, SPI and UART clocks; the capture clock's edges change
// `pwm_skip`, a port, so they evaluate).
void clock_edge(Vharness& model) {
    do {
        while (Vharness___024root___eval_phase__act(model.rootp)) {
        }
    } while (Vharness___024root___eval_phase__nba(model.rootp));
}

// One Verilated harness with its own context.
struct Instance {
    VerilatedContext context;
    Vharness model;

    Instance() : model{&context, "harness"} { model.eval(); }  // initial blocks, first settle

    // A model's scopes unregister from this thread's current context, which is the last
    // one created here, not necessarily theirs (with two harnesses, destroying the first
    // one through the second's freed context deadlocked): make it this one's. The body
    // runs before the members' destructors.
    ~Instance() {
        Verilated::threadContextp(&context);
        model.final();
    }
};

struct Harness {
    Instance instance;
    Vharness& model = instance.model;
    uint64_t sys_cycles = 0;
    uint64_t pwm_cycles = 0;
    uint64_t uart_cycles = 0;
    Cost costs[COST_SLOTS];
    std::string error;
    bool by_event = true;  // capture-clock edges stand for every quiet tick
    bool uart_by_event = true;  // UART edges likewise for every quiet cycle
    bool i2c_by_event = true;  // I2C edges likewise

    Harness() {
        model.pwm_skip = 0;
        model.uart_skip = 0;
        model.i2c_skip = 0;
    }

    void sync_cycle() {
        model.rootp->SYNC_CLOCK = 1;
        clock_edge(model);
        ++sys_cycles;
    }

    // The SPI controller's clock: the system clock's rate, so its cycles count as system
    // cycles (bus time).
    void spi_cycle() {
        model.rootp->SPI_CLOCK = 1;
        clock_edge(model);
        ++sys_cycles;
    }

    // The I2C clock: the I2C controller and chips alone, at the system clock's rate (bus
    // time, as the SPI controller's).
    void i2c_cycle() {
        model.rootp->I2C_CLOCK = 1;
        clock_edge(model);
        ++sys_cycles;
    }

    // One I2C edge standing for every cycle `i2c_quiet` says is quiet (see the top).
    void i2c_event() {
        sys_cycles += skipping_edge(model.rootp->I2C_CLOCK, model.i2c_skip, model.i2c_quiet);
    }

    void pwm_cycle() {
        model.rootp->PWM_CLOCK = 1;
        evaluate(model);
        ++pwm_cycles;
    }

    // `count` ticks of the capture clock, each quiet stretch in one edge (see the top).
    void pwm_ticks(uint64_t count) {
        while (count != 0) {
            const uint64_t quiet = by_event ? model.pwm_quiet : 1;
            const uint64_t ticks = std::clamp<uint64_t>(quiet, 1, count);
            model.pwm_skip = static_cast<SData>(ticks - 1);
            pwm_cycle();
            pwm_cycles += ticks - 1;
            count -= ticks;
        }
        model.pwm_skip = 0;
    }

    void uart_cycle() {
        model.rootp->UART_CLOCK = 1;
        clock_edge(model);
        ++uart_cycles;
    }

    // One UART edge standing for every cycle `uart_quiet` says is quiet (see the top).
    void uart_event() {
        uart_cycles += skipping_edge(model.rootp->UART_CLOCK, model.uart_skip, model.uart_quiet);
    }

    // One edge of `clock` standing for the cycles `quiet` says are quiet (at least one),
    // returned. The skip is a port, so an edge that changes it evaluates the inputs too;
    // one with the skip as it was (mostly none, around bus events) is a clock edge alone.
    template <typename Skip, typename Quiet>
    uint64_t skipping_edge(CData& clock, Skip& skip, const Quiet& quiet) {
        const uint64_t cycles = std::max<uint64_t>(quiet, 1);
        const auto next = static_cast<Skip>(cycles - 1);
        clock = 1;
        if (next == skip) {
            clock_edge(model);
        } else {
            skip = next;
            evaluate(model);
        }
        return cycles;
    }

    // The gated clock's rule: whole cycles while `enable` is high, checked after each.
    template <typename Cycle>
    bool run_gated(const CData& enable, Cycle cycle, const char* clock, const char* what) {
        evaluate(model);
        for (uint64_t cycles = 0; enable; ++cycles) {
            if (cycles == CYCLE_LIMIT) {
                error = std::string(what) + ": the " + clock + " clock still runs after " +
                        std::to_string(CYCLE_LIMIT) + " cycles";
                return false;
            }
            cycle();
        }
        return true;
    }

    bool run_sync(const char* what) {
        return run_gated(model.rootp->SYNC_ENABLE, [this] { sync_cycle(); }, "system", what);
    }

    bool run_i2c(const char* what) {
        if (!i2c_by_event) {
            return run_gated(model.rootp->I2C_ENABLE, [this] { i2c_cycle(); }, "I2C", what);
        }
        const bool ran = run_gated(model.rootp->I2C_ENABLE, [this] { i2c_event(); }, "I2C", what);
        model.i2c_skip = 0;  // the system clock's edges clock the bus one cycle each
        return ran;
    }

    bool run_uart(const char* what) {
        if (!uart_by_event) {
            return run_gated(model.rootp->UART_ENABLE, [this] { uart_cycle(); }, "UART", what);
        }
        const bool ran =
            run_gated(model.rootp->UART_ENABLE, [this] { uart_event(); }, "UART", what);
        model.uart_skip = 0;
        return ran;
    }

    bool run_spi(const char* what) {
        return run_gated(model.rootp->SPI_ENABLE, [this] { spi_cycle(); }, "SPI", what);
    }

    // The clocks a request runs, in turn: the system clock; the I2C clock; the UART
    // clock; or the SPI controller's, then the system clock's settle cycles.
    enum class Clocks { SYNC, I2C, UART, SPI };

    // Flip a peripheral's request toggle and clock until it has acknowledged.
    bool request(CData& request, const CData& acknowledge, const char* what,
                 Clocks clocks = Clocks::SYNC) {
        request ^= 1;
        const bool ran = clocks == Clocks::I2C    ? run_i2c(what)
                         : clocks == Clocks::UART ? run_uart(what)
                         : clocks == Clocks::SPI  ? run_spi(what) && run_sync(what)
                                                  : run_sync(what);
        if (!ran) return false;
        if (acknowledge != request) {
            error = std::string(what) + ": the clock stopped before the acknowledge";
            return false;
        }
        return true;
    }

    bool fail(const std::string& why) {
        error = why;
        return false;
    }
};

template <typename T>
constexpr size_t port_bytes() {
    if constexpr (VlIsVlWide<T>::value) {
        return T::Words * sizeof(EData);
    } else {
        return sizeof(T);
    }
}

template <typename T>
bool put(Harness& h, T& port, const uint8_t* bytes, size_t count, const char* name) {
    if (count > port_bytes<T>()) {
        return h.fail(std::string(name) + ": " + std::to_string(count) + " bytes for a " +
                      std::to_string(port_bytes<T>()) + "-byte port");
    }
    if constexpr (VlIsVlWide<T>::value) {
        std::memset(port.data(), 0, port_bytes<T>());
        std::memcpy(port.data(), bytes, count);
    } else {
        T value = 0;
        std::memcpy(&value, bytes, count);
        port = value;
    }
    return true;
}

template <typename T>
bool get(Harness& h, const T& port, uint8_t* bytes, size_t count, const char* name) {
    if (count > port_bytes<T>()) {
        return h.fail(std::string(name) + ": " + std::to_string(count) + " bytes asked of a " +
                      std::to_string(port_bytes<T>()) + "-byte port");
    }
    if constexpr (VlIsVlWide<T>::value) {
        std::memcpy(bytes, port.data(), count);
    } else {
        const T value = port;
        std::memcpy(bytes, &value, count);
    }
    return true;
}

int status(bool ok) { return ok ? 0 : -1; }

}  // namespace

#define EXPORT __attribute__((visibility("default")))

extern "C" {

EXPORT void* nh_create() {
    return new Harness();
}

EXPORT void nh_destroy(void* handle) {
    auto* harness = static_cast<Harness*>(handle);
    delete harness;
    Verilated::threadContextp(nullptr);  // and the last context: none is left dangling
}

EXPORT const char* nh_error(void* handle) { return static_cast<Harness*>(handle)->error.c_str(); }

EXPORT int nh_cycles(void* handle, uint64_t* sys_cycles, uint64_t* pwm_cycles,
                     uint64_t* uart_cycles) {
    auto* h = static_cast<Harness*>(handle);
    *sys_cycles = h->sys_cycles;
    *pwm_cycles = h->pwm_cycles;
    *uart_cycles = h->uart_cycles;
    return 0;
}

// Every slot's calls, cycles and nanoseconds, three words a slot (`words` of them).
EXPORT int nh_costs(void* handle, uint64_t* out, size_t words) {
    auto* h = static_cast<Harness*>(handle);
    if (words != 3 * COST_SLOTS) {
        return status(h->fail("nh_costs: " + std::to_string(words) + " words for " +
                              std::to_string(COST_SLOTS) + " slots of three"));
    }
    for (size_t slot = 0; slot < COST_SLOTS; ++slot) {
        out[3 * slot] = h->costs[slot].calls;
        out[3 * slot + 1] = h->costs[slot].cycles;
        out[3 * slot + 2] = h->costs[slot].ns;
    }
    return 0;
}

// Reset every domain: `rst` high for these cycles of each clock, then the system and
// UART clocks run until they stop by themselves.
EXPORT int nh_reset(void* handle, uint32_t sys_cycles, uint32_t pwm_cycles,
                    uint32_t uart_cycles) {
    auto* h = static_cast<Harness*>(handle);
    Vharness& m = h->model;
    m.rst = 1;
    evaluate(m);
    for (uint32_t i = 0; i < sys_cycles; ++i) h->sync_cycle();
    for (uint32_t i = 0; i < sys_cycles; ++i) h->spi_cycle();
    for (uint32_t i = 0; i < pwm_cycles; ++i) h->pwm_cycle();
    for (uint32_t i = 0; i < uart_cycles; ++i) h->uart_cycle();
    m.rst = 0;
    return status(h->run_sync("reset") && h->run_spi("reset") && h->run_uart("reset"));
}

// One SPI transfer of `length` bytes; `tx` and `rx` hold `bytes` (the buffer's size).
EXPORT int nh_spi(void* handle, uint32_t device, uint32_t length, uint32_t divider, uint32_t mode3,
           const uint8_t* tx, uint8_t* rx, size_t bytes) {
    auto* h = static_cast<Harness*>(handle);
    if (device >= SPI_SLOTS) return status(h->fail("SPI device " + std::to_string(device)));
    const Charge charge{h->costs[device], h->sys_cycles};
    Vharness& m = h->model;
    m.spi_device = device;
    m.spi_length = length;
    m.spi_divider = divider;
    m.spi_mode3 = mode3;
    bool ok = put(*h, m.spi_tx, tx, bytes, "spi_tx") &&
              h->request(m.spi_request, m.spi_acknowledge, "SPI transfer",
                         Harness::Clocks::SPI) &&
              get(*h, m.spi_rx, rx, bytes, "spi_rx");
    return status(ok);
}

// One I2C write/read; `nack_index` is -1 when every byte was acknowledged, else the index
// of the refused byte (0 the address).
EXPORT int nh_i2c(void* handle, uint32_t address, uint32_t write_len, uint32_t read_len, uint32_t fast,
           const uint8_t* tx, size_t tx_bytes, uint8_t* rx, size_t rx_bytes,
           int32_t* nack_index) {
    auto* h = static_cast<Harness*>(handle);
    const Charge charge{h->costs[I2C_SLOT + (address & 0x7f)], h->sys_cycles};
    Vharness& m = h->model;
    m.i2c_address = address;
    m.i2c_write_len = write_len;
    m.i2c_read_len = read_len;
    m.i2c_fast = fast;
    bool ok = put(*h, m.i2c_tx, tx, tx_bytes, "i2c_tx") &&
              h->request(m.i2c_request, m.i2c_acknowledge, "I2C transfer",
                         Harness::Clocks::I2C) &&
              get(*h, m.i2c_rx, rx, rx_bytes, "i2c_rx");
    *nack_index = m.i2c_nack ? static_cast<int32_t>(m.i2c_nack_index) : -1;
    return status(ok);
}

// The host writer's burst: `count` packed (address, data) words, commit, chips settled.
EXPORT int nh_host_write(void* handle, const uint8_t* words, size_t bytes, uint32_t count) {
    auto* h = static_cast<Harness*>(handle);
    const Charge charge{h->costs[HOST_WRITE_SLOT], h->sys_cycles};
    Vharness& m = h->model;
    m.host_count = count;
    bool ok = put(*h, m.host_words, words, bytes, "host_words") &&
              h->request(m.host_request, m.host_acknowledge, "host-port write");
    return status(ok);
}

// The host reader's burst: every result word, frozen in one cycle.
EXPORT int nh_host_read(void* handle, uint8_t* words, size_t bytes) {
    auto* h = static_cast<Harness*>(handle);
    const Charge charge{h->costs[HOST_READ_SLOT], h->sys_cycles};
    Vharness& m = h->model;
    bool ok = h->request(m.read_request, m.read_acknowledge, "host-port read") &&
              get(*h, m.read_words, words, bytes, "read_words");
    return status(ok);
}

// The GPS UART, on the UART clock alone: send `tx_len` bytes at `divider` cycles per bit,
// then listen until the receiver's line rests; the peer's receive buffer is copied to `rx`
// (up to `rx_bytes`; what arrived since the previous call is its last `rx_len` bytes) and
// the line time of the last byte (UART cycles) to `line_cycles`.
EXPORT int nh_uart(void* handle, uint32_t divider, const uint8_t* tx, size_t tx_bytes,
                   uint32_t tx_len, uint8_t* rx, size_t rx_bytes, uint32_t* rx_len,
                   uint32_t* line_cycles) {
    auto* h = static_cast<Harness*>(handle);
    const Charge charge{h->costs[UART_SLOT], h->uart_cycles};
    Vharness& m = h->model;
    m.uart_divider = divider;
    m.uart_tx_len = tx_len;
    bool ok = put(*h, m.uart_tx, tx, tx_bytes, "uart_tx") &&
              h->request(m.uart_request, m.uart_acknowledge, "UART exchange",
                         Harness::Clocks::UART) &&
              get(*h, m.uart_rx, rx, rx_bytes, "uart_rx");
    *rx_len = m.uart_rx_len;
    *line_cycles = m.uart_line_cycles;
    return status(ok);
}

// The PWM generator's inputs: packed widths (ticks) and the period (ticks, 0 stops it).
EXPORT int nh_pwm_set(void* handle, const uint8_t* widths, size_t bytes, uint32_t period_ticks) {
    auto* h = static_cast<Harness*>(handle);
    Vharness& m = h->model;
    m.pwm_period_ticks = period_ticks;
    return status(put(*h, m.pwm_width_ticks, widths, bytes, "pwm_width_ticks"));
}

// `count` cycles of the capture clock (the generator's and the capture core's domains).
EXPORT int nh_pwm_cycles(void* handle, uint64_t count) {
    auto* h = static_cast<Harness*>(handle);
    const Charge charge{h->costs[PWM_SLOT], h->pwm_cycles};
    evaluate(h->model);  // inputs written since the last eval settle before the first edge
    h->pwm_ticks(count);
    return 0;
}

// Whether capture-clock edges stand for every quiet tick (1, the default) or one tick each.
EXPORT int nh_pwm_by_event(void* handle, int enabled) {
    auto* h = static_cast<Harness*>(handle);
    h->by_event = enabled != 0;
    return 0;
}

// Whether UART edges stand for every quiet cycle (1, the default) or one cycle each.
EXPORT int nh_uart_by_event(void* handle, int enabled) {
    auto* h = static_cast<Harness*>(handle);
    h->uart_by_event = enabled != 0;
    return 0;
}

// Whether I2C edges stand for every quiet cycle (1, the default) or one cycle each.
EXPORT int nh_i2c_by_event(void* handle, int enabled) {
    auto* h = static_cast<Harness*>(handle);
    h->i2c_by_event = enabled != 0;
    return 0;
}

}  // extern "C"

