"""Schema version 2 (issue 32): limits the same on SQLite and PostgreSQL (unbounded text,
64-bit sizes), entry numbers never reused (SQLite AUTOINCREMENT; PostgreSQL's sequence
already was), inputs and parameters in the order written (an ``id`` each), a parameter
value that is not a number stored as null.

Revision ID: 0002
Revises: 0001
"""
import sqlalchemy as sa
from alembic import op

revision = "0002"
down_revision = "0001"
branch_labels = None
depends_on = None

TEXT = {"entries": ("kind", "created_utc", "cell", "robot", "robot_sha256",
                    "planecal_version", "outcome", "result_sha256"),
        "inputs": ("role", "sha256"), "parameters": ("name", "unit", "status"),
        "meta": ("key",)}


def upgrade() -> None:
    sqlite = op.get_bind().dialect.name == "sqlite"
    kw = {"entries": {"table_kwargs": {"sqlite_autoincrement": True}}} if sqlite else {}
    for table, cols in TEXT.items():
        with op.batch_alter_table(table, recreate="always" if sqlite else "auto",
                                  **kw.get(table, {})) as b:
            for c in cols:
                b.alter_column(c, type_=sa.Text())
            if table == "inputs":
                b.alter_column("bytes", type_=sa.BigInteger())
            if table == "parameters":
                b.alter_column("value", existing_type=sa.Float(), nullable=True)
            if sqlite and table in ("inputs", "parameters"):
                b.add_column(sa.Column("id", sa.Integer, primary_key=True, autoincrement=True))
    if sqlite:  # numbers a version-1 history may have freed (its last entry deleted: its
        # inputs and parameters are still there) are not given again
        op.execute("DELETE FROM sqlite_sequence WHERE name = 'entries'")
        op.execute("INSERT INTO sqlite_sequence (name, seq) SELECT 'entries', max(m) FROM "
                   "(SELECT max(id) AS m FROM entries UNION ALL SELECT max(entry_id) FROM "
                   "inputs UNION ALL SELECT max(entry_id) FROM parameters) WHERE m IS NOT NULL "
                   "HAVING count(*) > 0")
    else:  # a sequence numbers the existing rows in their stored order
        for table in ("inputs", "parameters"):
            op.execute(f"ALTER TABLE {table} ADD COLUMN id SERIAL PRIMARY KEY")
    op.execute("UPDATE meta SET value = '2' WHERE key = 'schema_version'")


def downgrade() -> None:
    raise NotImplementedError("a history is not downgraded: its backup is the version-1 copy")
