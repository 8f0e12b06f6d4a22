# daemon/module.mk: store.c embeds daemon/schema.sql (.incbin), so it is rebuilt when the schema changes.
$(BUILD)/obj/daemon/store.o: daemon/schema.sql
