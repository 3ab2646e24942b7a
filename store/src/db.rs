//! One small interface over both back ends' connections, for the code that reads and writes
//! the same rows on either (recordings, `record.rs`): statements with `?N` parameters, values
//! of five kinds.

use std::path::Path;

use postgres::types::{ToSql, Type};

use crate::sql::numbered;
use crate::StoreError;

/// A column value.
#[derive(Clone, Debug, PartialEq)]
pub(crate) enum V {
    /// An integer.
    I(i64),
    /// A float.
    R(f64),
    /// Text.
    T(String),
    /// Bytes.
    B(Vec<u8>),
    /// NULL.
    N,
}

impl V {
    /// The integer, or an error naming `what`.
    pub fn int(&self, what: &str) -> Result<i64, StoreError> {
        match self {
            V::I(i) => Ok(*i),
            v => Err(StoreError::Row(format!("{what}: {v:?} is not an integer"))),
        }
    }

    /// The integer, or `None` for NULL.
    pub fn opt_int(&self, what: &str) -> Result<Option<i64>, StoreError> {
        match self {
            V::N => Ok(None),
            v => v.int(what).map(Some),
        }
    }

    /// The float.
    pub fn real(&self, what: &str) -> Result<f64, StoreError> {
        match self {
            V::R(f) => Ok(*f),
            V::I(i) => Ok(*i as f64),
            v => Err(StoreError::Row(format!("{what}: {v:?} is not a number"))),
        }
    }

    /// The text.
    pub fn text(&self, what: &str) -> Result<&str, StoreError> {
        match self {
            V::T(s) => Ok(s),
            v => Err(StoreError::Row(format!("{what}: {v:?} is not text"))),
        }
    }

    /// The bytes.
    pub fn bytes(&self, what: &str) -> Result<&[u8], StoreError> {
        match self {
            V::B(b) => Ok(b),
            v => Err(StoreError::Row(format!("{what}: {v:?} is not bytes"))),
        }
    }
}

/// Statements on one connection or transaction.
pub(crate) trait Sql {
    /// Run `sql`; rows changed.
    fn exec(&mut self, sql: &str, params: &[V]) -> Result<u64, StoreError>;
    /// Run a query; its rows.
    fn rows(&mut self, sql: &str, params: &[V]) -> Result<Vec<Vec<V>>, StoreError>;
}

impl rusqlite::ToSql for V {
    fn to_sql(&self) -> rusqlite::Result<rusqlite::types::ToSqlOutput<'_>> {
        use rusqlite::types::{ToSqlOutput, Value, ValueRef};
        Ok(match self {
            V::I(i) => ToSqlOutput::Owned(Value::Integer(*i)),
            V::R(f) => ToSqlOutput::Owned(Value::Real(*f)),
            V::T(s) => ToSqlOutput::Borrowed(ValueRef::Text(s.as_bytes())),
            V::B(b) => ToSqlOutput::Borrowed(ValueRef::Blob(b)),
            V::N => ToSqlOutput::Owned(Value::Null),
        })
    }
}

/// A SQLite connection (or a transaction: it derefs to one) and its file, for errors.
pub(crate) struct Lite<'a>(pub &'a rusqlite::Connection, pub &'a Path);

impl Sql for Lite<'_> {
    fn exec(&mut self, sql: &str, params: &[V]) -> Result<u64, StoreError> {
        self.0
            .execute(sql, rusqlite::params_from_iter(params.iter()))
            .map(|n| n as u64)
            .map_err(crate::sqlite::db_err(self.1))
    }

    fn rows(&mut self, sql: &str, params: &[V]) -> Result<Vec<Vec<V>>, StoreError> {
        use rusqlite::types::ValueRef;
        let err = crate::sqlite::db_err(self.1);
        let mut st = self.0.prepare_cached(sql).map_err(&err)?;
        let n = st.column_count();
        let mut rows = st
            .query(rusqlite::params_from_iter(params.iter()))
            .map_err(&err)?;
        let mut out = Vec::new();
        while let Some(r) = rows.next().map_err(&err)? {
            let mut row = Vec::with_capacity(n);
            for i in 0..n {
                row.push(match r.get_ref(i).map_err(&err)? {
                    ValueRef::Null => V::N,
                    ValueRef::Integer(x) => V::I(x),
                    ValueRef::Real(x) => V::R(x),
                    ValueRef::Text(t) => V::T(String::from_utf8_lossy(t).into_owned()),
                    ValueRef::Blob(b) => V::B(b.to_vec()),
                });
            }
            out.push(row);
        }
        Ok(out)
    }
}

/// A PostgreSQL client or transaction and its redacted URL, for errors.
pub(crate) struct Pg<'a, C: postgres::GenericClient>(pub &'a mut C, pub &'a str);

fn pg_params(params: &[V]) -> Vec<Box<dyn ToSql + Sync>> {
    params
        .iter()
        .map(|v| -> Box<dyn ToSql + Sync> {
            match v {
                V::I(i) => Box::new(*i),
                V::R(f) => Box::new(*f),
                V::T(s) => Box::new(s.clone()),
                V::B(b) => Box::new(b.clone()),
                V::N => Box::new(Option::<i64>::None),
            }
        })
        .collect()
}

impl<C: postgres::GenericClient> Sql for Pg<'_, C> {
    fn exec(&mut self, sql: &str, params: &[V]) -> Result<u64, StoreError> {
        let owned = pg_params(params);
        let refs: Vec<&(dyn ToSql + Sync)> = owned.iter().map(|b| b.as_ref()).collect();
        self.0
            .execute(numbered(sql).as_str(), &refs)
            .map_err(crate::postgres::db_err(self.1))
    }

    fn rows(&mut self, sql: &str, params: &[V]) -> Result<Vec<Vec<V>>, StoreError> {
        let err = crate::postgres::db_err(self.1);
        let owned = pg_params(params);
        let refs: Vec<&(dyn ToSql + Sync)> = owned.iter().map(|b| b.as_ref()).collect();
        let mut out = Vec::new();
        for r in self.0.query(numbered(sql).as_str(), &refs).map_err(&err)? {
            let mut row = Vec::with_capacity(r.len());
            for (i, c) in r.columns().iter().enumerate() {
                let t = c.type_();
                let v = if *t == Type::INT8 {
                    r.try_get::<_, Option<i64>>(i)
                        .map_err(&err)?
                        .map_or(V::N, V::I)
                } else if *t == Type::INT4 {
                    r.try_get::<_, Option<i32>>(i)
                        .map_err(&err)?
                        .map_or(V::N, |x| V::I(i64::from(x)))
                } else if *t == Type::FLOAT8 {
                    r.try_get::<_, Option<f64>>(i)
                        .map_err(&err)?
                        .map_or(V::N, V::R)
                } else if *t == Type::TEXT || *t == Type::VARCHAR || *t == Type::NAME {
                    r.try_get::<_, Option<String>>(i)
                        .map_err(&err)?
                        .map_or(V::N, V::T)
                } else if *t == Type::BYTEA {
                    r.try_get::<_, Option<Vec<u8>>>(i)
                        .map_err(&err)?
                        .map_or(V::N, V::B)
                } else {
                    return Err(StoreError::Row(format!("column {} of type {t}", c.name())));
                };
                row.push(v);
            }
            out.push(row);
        }
        Ok(out)
    }
}
