"""u-blox NEO-M8N GNSS receiver on UART: UBX layouts, RTL core, TLM twin, PX4 decoder."""
