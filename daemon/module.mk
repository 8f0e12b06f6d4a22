# daemon/module.mk: store_migrate.c embeds daemon/schema.sql (.incbin), so it is rebuilt when the schema changes.
$(BUILD)/obj/daemon/store_migrate.o: daemon/schema.sql
